#!/usr/bin/env python3
"""dhct side by side with peer methods on the same simulated image, in one run.

Usage:
    cargo run --release -p dhct-bench --bin headline -- --sizes "" --repeats 1 \
        --peers-dir "$PWD/target/peers" [--peer-size 1024] [--peer-static]
    python3 scripts/peers/compare.py "$PWD/target/peers" [--json OUT.json]

The bench binary writes into the directory: `trace.npy` (the simulated headline-physics
trace image, metres, display orientation), `matches_trace.csv` (every trace feature dhct
found, matched to the simulator's truth: found and true controller position in px, dhct's
corrected and the true sample position in m) and `ours.json` (geometry, dhct's stage
times and accuracy, measured in the same run).

Peers (installed with pip into target/tmp/peers-venv; a package that fails to install is
skipped with the reason printed, the others still run):

* Atomap 0.4 2-D Gaussian refinement (`get_atom_positions` +
  `refine_atom_positions_using_2d_gaussian`) on the trace, scored on equal terms with dhct's
  feature finding: the interior truth atoms both found, the 2-D rms error against the true
  controller positions after removing each method's mean offset (a pixel-centre convention
  is not a localisation error; the offsets are printed), and the time on that one image
  (dhct's from its run over both images, 2 threads; Atomap in one process).
* stmpy (package getstmpy) Lawler-Fujita: `stmpy.driftcorr.phasemap(method='convolution')`,
  `fixphaseslip`, `driftmap` (the steps of `local_corr(method='convolution')`), followed by
  the global affine map below to the known lattice. The displacement field is applied to
  dhct's found feature positions, not to the image: stmpy's image step
  (`driftcorr(method='convolution')`, `_apply_drift_field`) builds N_rows x N_pixels arrays
  (8 GB real + 16 GB complex at 1024^2), so it is timed on a 256^2 crop only.
* Global affine correction: the three first-order Bragg peaks of |FFT| (Hann window,
  sub-bin centroid) give the measured reciprocal lattice; the affine map to the ideal
  lattice (known constant, measured orientation) is applied to the found positions.

Every method's corrected positions are compared with the true sample positions after the
best rigid motion (rotation + translation); dhct's are also reported after a translation
only. Ratios are dhct / peer for errors and peer / dhct for times.
"""
import json
import os
import subprocess
import sys
import time
import venv

HERE = os.path.dirname(os.path.abspath(__file__))
VENV = os.path.join(HERE, "..", "..", "target", "tmp", "peers-venv")
PACKAGES = ["numpy", "scipy", "atomap", "getstmpy"]


def ensure_venv():
    """Creates the venv and installs each package; returns (python, {package: error})."""
    python = os.path.join(VENV, "bin", "python")
    if not os.path.exists(python):
        venv.EnvBuilder(with_pip=True).create(VENV)
    failed = {}
    modules = {"numpy": "numpy", "scipy": "scipy", "atomap": "atomap.api",
               "getstmpy": "stmpy.driftcorr"}
    for package in PACKAGES:
        probe = subprocess.run([python, "-c", f"import {modules[package]}"],
                               capture_output=True, env=quiet_env())
        if probe.returncode == 0:
            continue
        install = subprocess.run([python, "-m", "pip", "install", "-q", package],
                                 capture_output=True, text=True)
        if install.returncode != 0:
            failed[package] = (install.stderr or install.stdout).strip().splitlines()[-1:]
    return python, failed


def quiet_env():
    return dict(os.environ, MPLBACKEND="Agg", TQDM_DISABLE="1", PYTHONWARNINGS="ignore")


# ---------------------------------------------------------------- geometry helpers

def rigid_rms(p, q):
    """2-D rms of q - (R p + t) for the best rotation R and translation t (Kabsch)."""
    import numpy as np
    pc, qc = p - p.mean(0), q - q.mean(0)
    u, _, vt = np.linalg.svd(pc.T @ qc)
    d = np.sign(np.linalg.det(u @ vt))
    r = (u @ np.diag([1.0, d]) @ vt).T
    return float(np.sqrt(np.mean(np.sum((qc - pc @ r.T) ** 2, axis=1))))


def translation_rms(p, q):
    import numpy as np
    d = q - p
    d = d - d.mean(0)
    return float(np.sqrt(np.mean(np.sum(d ** 2, axis=1))))


def affine_rms(p, q):
    """2-D rms after the best affine map p -> q (an oracle: fitted to the truth)."""
    import numpy as np
    design = np.column_stack([np.ones(len(p)), p])
    coef, *_ = np.linalg.lstsq(design, q, rcond=None)
    return float(np.sqrt(np.mean(np.sum((design @ coef - q) ** 2, axis=1))))


def bragg_peaks(image, nn_px, hexagonal=True):
    """First-order Bragg peaks of a hexagonal lattice with NN distance nn_px (pixels).

    Returns three reciprocal vectors (cycles/px, [kx, ky]) 60 degrees apart in order, each
    refined by the intensity centroid of a 5 x 5 bin patch, and their nearest integer bins.
    """
    import numpy as np
    rows, cols = image.shape
    window = np.outer(np.hanning(rows), np.hanning(cols))
    f = np.abs(np.fft.fftshift(np.fft.fft2((image - image.mean()) * window)))
    ky = (np.arange(rows) - rows // 2) / rows
    kx = (np.arange(cols) - cols // 2) / cols
    kxx, kyy = np.meshgrid(kx, ky)
    radius = np.hypot(kxx, kyy)
    expected = 2.0 / (np.sqrt(3.0) * nn_px) if hexagonal else 1.0 / nn_px
    ring = (radius > 0.6 * expected) & (radius < 1.5 * expected) & (kyy >= 0)
    g = np.where(ring, f, 0.0)
    peaks = []
    for _ in range(3):
        r, c = np.unravel_index(np.argmax(g), g.shape)
        patch = f[r - 2:r + 3, c - 2:c + 3] ** 2
        yy, xx = np.mgrid[-2:3, -2:3]
        dr = (patch * yy).sum() / patch.sum()
        dc = (patch * xx).sum() / patch.sum()
        peaks.append(((c - cols // 2 + dc) / cols, (r - rows // 2 + dr) / rows,
                      c - cols // 2, r - rows // 2))
        # Suppress this peak (and its mirror, already excluded by ky >= 0) around it.
        g[max(r - 8, 0):r + 9, max(c - 8, 0):c + 9] = 0.0
    peaks.sort(key=lambda p: np.arctan2(p[1], p[0]))
    vectors = np.array([[p[0], p[1]] for p in peaks])
    bins = np.array([[p[2], p[3]] for p in peaks])
    return vectors, bins


def ideal_map(measured, nn_m):
    """Linear map M (m per px) with r_m = M r_px, from two measured reciprocal vectors
    (cycles/px, rows) to ideal ones of the known hexagonal lattice at the first vector's
    orientation with the same angular order (60 or 120 degrees)."""
    import numpy as np
    g = 2.0 / (np.sqrt(3.0) * nn_m)
    a1 = np.arctan2(measured[0][1], measured[0][0])
    a2 = np.arctan2(measured[1][1], measured[1][0])
    step = (a2 - a1 + np.pi) % (2 * np.pi) - np.pi
    ideal_step = min([np.pi / 3, 2 * np.pi / 3, -np.pi / 3, -2 * np.pi / 3],
                     key=lambda s: abs(s - step))
    ideal = g * np.array([[np.cos(a1), np.sin(a1)],
                          [np.cos(a1 + ideal_step), np.sin(a1 + ideal_step)]])
    return np.linalg.solve(ideal, measured)


def bilinear(field, x, y):
    import numpy as np
    rows, cols = field.shape
    x = np.clip(x, 0, cols - 1.000001)
    y = np.clip(y, 0, rows - 1.000001)
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    return ((1 - fx) * (1 - fy) * field[y0, x0] + fx * (1 - fy) * field[y0, x0 + 1]
            + (1 - fx) * fy * field[y0 + 1, x0] + fx * fy * field[y0 + 1, x0 + 1])


# ---------------------------------------------------------------- the peers

def run_atomap(image, truth_px, nn_px):
    import numpy as np
    import hyperspy.api as hs
    import atomap.api as am
    signal = hs.signals.Signal2D(image - image.min())
    start = time.perf_counter()
    # peak_local_max's footprint is a square of half-width `separation`, so 0.8 NN drops
    # about half of a hexagonal lattice; 0.6 NN finds all.
    positions = am.get_atom_positions(signal, separation=int(0.6 * nn_px))
    sublattice = am.Sublattice(positions, image=signal.data)
    sublattice.find_nearest_neighbors()
    sublattice.refine_atom_positions_using_2d_gaussian(percent_to_nn=0.4)
    seconds = time.perf_counter() - start
    found = np.column_stack([sublattice.x_position, sublattice.y_position])
    from scipy.spatial import cKDTree
    distance, nearest = cKDTree(found).query(truth_px)
    hit = distance < 0.3 * nn_px
    return {
        "features": int(len(found)),
        "seconds": seconds,
        "features_per_s": len(found) / seconds,
        "matched": int(hit.sum()),
        "recall": float(hit.mean()),
        "rms_px": float(np.sqrt(np.mean(distance[hit] ** 2))),
        # Atomap's position of each truth atom (NaN where it found none within 0.3 NN).
        "positions_px": np.where(hit[:, None], found[nearest], np.nan),
    }


def equal_terms(found_a, found_b, truth_px):
    """Both methods scored the same way: over the truth atoms both found, 2-D rms error as
    found and after removing each method's mean offset (a pixel-centre convention or a
    constant bias is not a localisation error)."""
    import numpy as np
    both = np.isfinite(found_a).all(axis=1) & np.isfinite(found_b).all(axis=1)
    scores = {"common_atoms": int(both.sum())}
    for name, found in (("dhct", found_a), ("peer", found_b)):
        error = found[both] - truth_px[both]
        offset = error.mean(axis=0)
        scores[name] = {
            "rms_px": float(np.sqrt(np.mean(np.sum(error ** 2, axis=1)))),
            "mean_offset_px": offset.tolist(),
            "rms_offset_removed_px": float(np.sqrt(np.mean(np.sum((error - offset) ** 2, axis=1)))),
        }
    return scores


def run_affine(image, found_px, sample_m, nn_m, pitch_m):
    import numpy as np
    start = time.perf_counter()
    vectors, _ = bragg_peaks(image, nn_m / pitch_m[0])
    m = ideal_map(vectors[:2], nn_m)
    corrected = found_px @ m.T
    seconds = time.perf_counter() - start
    return {"seconds": seconds, "rigid_rms_m": rigid_rms(corrected, sample_m),
            "bragg_cycles_per_px": vectors.tolist()}


def lawler_fujita_field(image, bins, sigma):
    """stmpy's convolution Lawler-Fujita steps for Bragg peaks at integer `bins`."""
    import numpy as np
    import stmpy.driftcorr as dfc
    rows, cols = image.shape
    centre = np.array([(cols - 1) // 2, (rows - 1) // 2])
    bp = np.array(bins[:2]) + centre
    thetax, thetay, q1, q2 = dfc.phasemap(image, bp=bp, method="convolution", sigma=sigma)
    phix = dfc.fixphaseslip(thetax, method="unwrap")
    phiy = dfc.fixphaseslip(thetay, method="unwrap")
    ux, uy = dfc.driftmap(phix, phiy, q1, q2, method="convolution")
    return ux, uy, q1, q2


def run_lawler_fujita(image, found_px, sample_m, nn_m, pitch_m, sigma):
    import numpy as np
    start = time.perf_counter()
    _, bins = bragg_peaks(image, nn_m / pitch_m[0])
    ux, uy, q1, q2 = lawler_fujita_field(image - image.mean(), bins, sigma)
    # stmpy's u is the displacement of the imaged lattice from the reference lattice of
    # the integer-bin Bragg vectors (a feature seen at p belongs at p - u(p)); the sign is
    # checked on a synthetic shifted lattice by stmpy_sign().
    sign = stmpy_sign()
    results = {}
    for factor, name in [(sign, "lf"), (-sign, "opposite_sign")]:
        p = found_px - factor * np.column_stack(
            [bilinear(ux, found_px[:, 0], found_px[:, 1]),
             bilinear(uy, found_px[:, 0], found_px[:, 1])])
        # After LF the lattice has the integer-bin periods q1, q2: map those to the ideal.
        measured = np.array([q1, q2]) / (2 * np.pi)
        results[name] = p @ ideal_map(measured, nn_m).T
    seconds = time.perf_counter() - start
    # Keep only the image interior (1/8 of the width each side) too: LF's Gaussian
    # convolution has edge effects.
    rows, cols = image.shape
    inner = ((found_px[:, 0] > cols / 8) & (found_px[:, 0] < cols * 7 / 8)
             & (found_px[:, 1] > rows / 8) & (found_px[:, 1] < rows * 7 / 8))
    return {
        "sigma_px": sigma,
        "seconds": seconds,
        "rigid_rms_m": rigid_rms(results["lf"], sample_m),
        "rigid_rms_interior_m": rigid_rms(results["lf"][inner], sample_m[inner]),
        "rigid_rms_opposite_sign_m": rigid_rms(results["opposite_sign"], sample_m),
    }


def stmpy_sign():
    """+1 if stmpy's drift field u equals the displacement of the imaged features (checked
    on a square cosine lattice shifted by a known amount), else -1."""
    import numpy as np
    import stmpy.driftcorr as dfc
    n, period, shift = 128, 16, 1.25
    y, x = np.mgrid[0:n, 0:n].astype(float)
    image = np.cos(2 * np.pi * (x - shift) / period) + np.cos(2 * np.pi * y / period)
    c = (n - 1) // 2
    bp = np.array([[c + n // period, c], [c, c + n // period]])
    tx, ty, q1, q2 = dfc.phasemap(image, bp=bp, method="convolution", sigma=10)
    ux, _ = dfc.driftmap(dfc.fixphaseslip(tx), dfc.fixphaseslip(ty), q1, q2,
                         method="convolution")
    u = ux[n // 2, n // 2]
    if abs(abs(u) - shift) > 0.05:
        raise RuntimeError(f"stmpy drift field self-test: {u} px for a {shift} px shift")
    return 1.0 if u > 0 else -1.0


def time_stmpy_image_step(image, nn_px, size=256):
    """Times stmpy's full `local_corr(method='convolution')`, image step included, on a
    size^2 crop (its image step needs N^3 memory)."""
    import numpy as np
    import stmpy.driftcorr as dfc
    crop = image[:size, :size] - image[:size, :size].mean()
    _, bins = bragg_peaks(crop, nn_px)
    centre = np.array([(size - 1) // 2, (size - 1) // 2])
    start = time.perf_counter()
    dfc.local_corr(crop, bp=np.array(bins[:2]) + centre, sigma=10, method="convolution")
    return time.perf_counter() - start


# ---------------------------------------------------------------- main

def run_inside(directory, out_json, failed):
    import numpy as np
    image = np.load(os.path.join(directory, "trace.npy"))
    ours = json.load(open(os.path.join(directory, "ours.json")))
    table = np.loadtxt(os.path.join(directory, "matches_trace.csv"), delimiter=",", skiprows=1)
    found_px, truth_px = table[:, 0:2], table[:, 2:4]
    corrected_m, sample_m = table[:, 4:6], table[:, 6:8]
    pitch = ours["pitch_m"]
    nn_m = ours["nn_m"]
    nn_px = nn_m / pitch[0]
    times = ours["times"]
    load = os.getloadavg()
    print(f"image {image.shape[1]} x {image.shape[0]} px, {len(table)} matched trace features; "
          f"load {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    report = {"image_pixels": list(image.shape), "matched_features": int(len(table)),
              "load_at_start": load, "skipped": {k: " ".join(v) for k, v in failed.items()}}

    # Ours.
    ours_feature_rms_px = float(np.sqrt(np.mean(np.sum((found_px - truth_px) ** 2, axis=1))))
    ours_rigid = rigid_rms(corrected_m, sample_m)
    ours_translation = translation_rms(corrected_m, sample_m)
    raw_m = found_px * np.array(pitch)
    distortion_s = times["model_s"] + times["correction_s"]
    chain_s = times["features_s"] + distortion_s
    report["dhct"] = {
        "features_per_s": ours["features_per_s"], "feature_rms_px_2d": ours_feature_rms_px,
        "threads": ours["threads"], "rigid_rms_m": ours_rigid,
        "translation_rms_m": ours_translation, "model_plus_correction_s": distortion_s,
        "features_model_correction_s": chain_s, "load": ours["load"],
        "raw_rigid_rms_m": rigid_rms(raw_m, sample_m),
        "oracle_affine_rms_m": affine_rms(raw_m, sample_m),
    }
    print(f"dhct:   {ours['features_per_s']:.0f} features/s ({ours['threads']} threads), "
          f"feature rms {ours_feature_rms_px:.4f} px; corrected rms vs truth "
          f"{ours_rigid * 1e12:.2f} pm rigid / {ours_translation * 1e12:.2f} pm translation; "
          f"model + correction {distortion_s:.3f} s, features + model + correction {chain_s:.3f} s "
          f"(load {ours['load']}, other processes {ours.get('other_cpus') or float('nan'):.2f} CPUs)")
    print(f"        raw positions {report['dhct']['raw_rigid_rms_m'] * 1e12:.1f} pm; best affine "
          f"fitted to the truth (oracle) {report['dhct']['oracle_affine_rms_m'] * 1e12:.2f} pm")

    if "atomap" in failed:
        print(f"atomap: skipped ({' '.join(failed['atomap'])})")
    else:
        a = run_atomap(image, truth_px, nn_px)
        fair = equal_terms(found_px, a.pop("positions_px"), truth_px)
        a["equal_terms"] = fair
        report["atomap"] = a
        # Our feature stage on the trace alone (the run timed both passes together).
        ours_trace_s = ours["trace_features"] / ours["features_per_s"]
        d, p = fair["dhct"], fair["peer"]
        print(f"atomap: {a['features']} atoms in {a['seconds']:.1f} s (1 process), "
              f"found {a['matched']} of dhct's {len(truth_px)} interior matched atoms")
        print(f"  equal terms, the {fair['common_atoms']} interior atoms both found: rms "
              f"{d['rms_offset_removed_px']:.4f} px (dhct) vs {p['rms_offset_removed_px']:.4f} px "
              f"(atomap) after each one's mean offset ({d['mean_offset_px'][0]:+.3f}, "
              f"{d['mean_offset_px'][1]:+.3f}) / ({p['mean_offset_px'][0]:+.3f}, "
              f"{p['mean_offset_px'][1]:+.3f}) px; as found {d['rms_px']:.4f} vs {p['rms_px']:.4f} px")
        print(f"  ratio: dhct/atomap rms {d['rms_offset_removed_px'] / p['rms_offset_removed_px']:.2f}; "
              f"time on the trace {ours_trace_s:.3f} s ({ours['threads']} threads) vs "
              f"{a['seconds']:.1f} s: {a['seconds'] / ours_trace_s:.0f}x")
        a["dhct_trace_seconds"] = ours_trace_s
        a["time_ratio_atomap_over_dhct"] = a["seconds"] / ours_trace_s
        a["rms_ratio_dhct_over_atomap"] = d["rms_offset_removed_px"] / p["rms_offset_removed_px"]

    if ours.get("static"):
        print("static lattice (--peer-static): localisation only; the distortion peers are not run")
        finish(report, out_json)
        return

    g = run_affine(image, found_px, sample_m, nn_m, pitch)
    report["fft_affine"] = g
    print(f"FFT affine: corrected rms {g['rigid_rms_m'] * 1e12:.2f} pm in {g['seconds']:.3f} s; "
          f"dhct/affine error ratio {ours_rigid / g['rigid_rms_m']:.4f}; "
          f"affine is {g['rigid_rms_m'] / ours_rigid:.1f}x worse")
    g["error_ratio_dhct_over_peer"] = ours_rigid / g["rigid_rms_m"]
    g["time_ratio_peer_over_dhct_model_correction"] = g["seconds"] / distortion_s

    if "getstmpy" in failed:
        print(f"stmpy Lawler-Fujita: skipped ({' '.join(failed['getstmpy'])})")
    else:
        period_px = nn_px * np.sqrt(3.0) / 2.0
        runs = []
        for sigma in [10.0, 2.0 * period_px, 4.0 * period_px]:
            lf = run_lawler_fujita(image, found_px, sample_m, nn_m, pitch, sigma)
            runs.append(lf)
            print(f"stmpy Lawler-Fujita (convolution, sigma {sigma:.1f} px) + affine: corrected "
                  f"rms {lf['rigid_rms_m'] * 1e12:.2f} pm (interior {lf['rigid_rms_interior_m'] * 1e12:.2f}"
                  f" pm; opposite sign {lf['rigid_rms_opposite_sign_m'] * 1e12:.1f} pm) in "
                  f"{lf['seconds']:.2f} s")
        best = min(runs, key=lambda r: r["rigid_rms_m"])
        crop_s = time_stmpy_image_step(image, nn_px)
        report["lawler_fujita"] = {"runs": runs, "best": best,
                                   "full_local_corr_256_crop_s": crop_s,
                                   "error_ratio_dhct_over_peer": ours_rigid / best["rigid_rms_m"],
                                   "time_ratio_peer_over_dhct_model_correction": best["seconds"] / distortion_s}
        print(f"  best sigma {best['sigma_px']:.1f} px: dhct/LF error ratio "
              f"{ours_rigid / best['rigid_rms_m']:.4f} (LF {best['rigid_rms_m'] / ours_rigid:.1f}x worse); "
              f"LF field {best['seconds']:.2f} s vs dhct model + correction {distortion_s:.3f} s; "
              f"stmpy's whole local_corr incl. its image step on a 256^2 crop: {crop_s:.2f} s")
    finish(report, out_json)


def finish(report, out_json):
    report["load_at_end"] = os.getloadavg()
    if out_json:
        with open(out_json, "w") as f:
            json.dump(report, f, indent=2)
        print(f"wrote {out_json}")


def main():
    args = sys.argv[1:]
    if not args or args[0].startswith("-"):
        print(__doc__)
        return 2
    directory = args[0]
    out_json = args[args.index("--json") + 1] if "--json" in args else None
    if os.environ.get("DHCT_PEERS_STAGE") == "inside":
        failed = json.loads(os.environ.get("DHCT_PEERS_FAILED", "{}"))
        run_inside(directory, out_json, failed)
        return 0
    try:
        python, failed = ensure_venv()
    except Exception as error:  # noqa: BLE001 - no venv at all: nothing can run
        print(f"skipped: cannot create the Python environment ({error})")
        return 0
    for package, reason in failed.items():
        print(f"{package}: install failed, that peer is skipped: {' '.join(reason)}")
    if "numpy" in failed or "scipy" in failed:
        print("skipped: numpy/scipy are needed by every comparison")
        return 0
    env = dict(quiet_env(), DHCT_PEERS_STAGE="inside", DHCT_PEERS_FAILED=json.dumps(failed))
    return subprocess.run([python, os.path.abspath(__file__)] + args, env=env).returncode


if __name__ == "__main__":
    sys.exit(main())
