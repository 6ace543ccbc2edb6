#!/usr/bin/env python3
"""Atomap's 2-D Gaussian refinement vs dhct feature finding on the same simulated image.

Usage:
    cargo bench -p dhct-features --bench features -- --write-dir "$PWD/target/atomap"
    python3 scripts/atomap_compare.py "$PWD/target/atomap"

(cargo bench runs in the crate's directory, hence the absolute path.)

Atomap is installed into a cached virtual environment (target/tmp/atomap-venv) with pip.
Prints features/s and rms position error vs the simulator's truth for both, and the ratios.
Exits 0 with "skipped: <reason>" only when Python itself cannot create the environment.
"""
import json
import os
import subprocess
import sys
import venv

HERE = os.path.dirname(os.path.abspath(__file__))
VENV = os.path.join(HERE, "..", "target", "tmp", "atomap-venv")


def ensure_venv():
    python = os.path.join(VENV, "bin", "python")
    if not os.path.exists(python):
        venv.EnvBuilder(with_pip=True).create(VENV)
    probe = subprocess.run([python, "-c", "import atomap"], capture_output=True)
    if probe.returncode != 0:
        subprocess.run([python, "-m", "pip", "install", "-q", "atomap"], check=True)
    return python


def run_inside(directory):
    import time

    import numpy as np
    import hyperspy.api as hs
    import atomap.api as am

    image = np.load(os.path.join(directory, "trace.npy"))
    truth = np.loadtxt(os.path.join(directory, "truth_trace.csv"), delimiter=",", skiprows=1)
    ours = json.load(open(os.path.join(directory, "dhct_timing.json")))
    # Same image and the same lattice knowledge: NN spacing 2.46 Å at 25 nm / 2048 px.
    nn_px = 2.46e-10 / (25e-9 / image.shape[1])
    signal = hs.signals.Signal2D(image - image.min())
    start = time.perf_counter()
    positions = am.get_atom_positions(signal, separation=int(0.8 * nn_px))
    sublattice = am.Sublattice(positions, image=signal.data)
    sublattice.find_nearest_neighbors()
    sublattice.refine_atom_positions_using_2d_gaussian(percent_to_nn=0.4)
    seconds = time.perf_counter() - start
    found = np.column_stack([sublattice.x_position, sublattice.y_position])
    errors = []
    for x, y in found:
        d = np.hypot(truth[:, 0] - x, truth[:, 1] - y).min()
        if d < 5.0:
            errors.append(d)
    rms = float(np.sqrt(np.mean(np.square(errors))))
    rate = len(found) / seconds
    print(f"atomap: {len(found)} atoms in {seconds:.1f} s ({rate:.0f} features/s, 1 process), "
          f"rms error {rms:.4f} px over {len(errors)} matched")
    print(f"dhct:   {ours['features_per_second']:.0f} features/s on {ours['threads']} threads, "
          f"rms error {ours['rms_px']:.4f} px")
    print(f"ratio:  dhct is {ours['features_per_second'] / rate:.0f}x faster; "
          f"rms error ratio dhct/atomap = {ours['rms_px'] / rms:.3f}")


def main():
    if len(sys.argv) != 2:
        print(__doc__)
        return 2
    if "--inside" in os.environ.get("DHCT_ATOMAP_STAGE", ""):
        run_inside(sys.argv[1])
        return 0
    try:
        python = ensure_venv()
    except Exception as error:  # noqa: BLE001 - any failure to build the venv is a skip reason
        print(f"skipped: cannot set up atomap ({error})")
        return 0
    env = dict(os.environ, DHCT_ATOMAP_STAGE="--inside", MPLBACKEND="Agg", TQDM_DISABLE="1")
    return subprocess.run([python, __file__, sys.argv[1]], env=env).returncode


if __name__ == "__main__":
    sys.exit(main())
