#!/usr/bin/env python3
"""Cross-check an SM4 file written by dhct against spym's independent SM4 reader, and
against Gwyddion's when the `gwyddion` program is installed.

Usage:
    spym_sm4_crosscheck.py FILE.sm4 EXPECTED.json [--venv DIR]

EXPECTED.json (written by crates/sm4-io/tests/sm4.rs) holds a list "pages", one per page in
file order, each with:
    label        spym's page label, e.g. "Topography_Forward"
    rows, columns
    x_scale, y_scale   the scales the file should state (m/px, signed)
    period       s per pixel
    z_unit       e.g. "m"
    tolerance    largest allowed |spym value - expected value|, in z units
    data         rows x columns values in dhct's display orientation (row 0 = top);
                 null for a missing (NaN) sample

spym's reader orients images as `p.data` with row 0 at the top when the y scale is negative
and mirrors columns when the x scale is negative, which is dhct's display orientation for the
scales dhct writes; physical values are `raw * RHK_Zscale + RHK_Zoffset`.

If `gwyddion` is on PATH, the file is also converted with `gwyddion --convert-to-gwy` (no GUI
needed) and the resulting .gwy file, read with the `gwyfile` package, must hold the same images
(Gwyddion shows row 0 at the top too) with the same physical width and height. Without it that
stage prints "gwyddion: not installed, stage skipped".

The first run creates a virtual environment (default: target/tmp/spym-venv next to this
repository, or --venv) and pip-installs spym, numpy and gwyfile into it; later runs reuse it. Only
spym's SM4 module (spym/io/rhksm4/_sm4.py, which needs just numpy) is loaded, so spym's
plotting and processing dependencies (xarray, scipy, ...) are not needed.

Exit status: 0 when every page matches, 1 on a mismatch, 2 on a setup failure.
"""

import json
import math
import os
import subprocess
import sys
import venv

READY_MARKER = ".dhct-spym-gwyfile-ready"
PACKAGES = ["spym==0.9.2", "numpy", "gwyfile==0.3.0"]
IN_VENV_FLAG = "DHCT_SPYM_CROSSCHECK_IN_VENV"


def default_venv():
    here = os.path.dirname(os.path.realpath(__file__))
    return os.path.join(os.path.dirname(here), "target", "tmp", "spym-venv")


def venv_python(directory):
    if os.name == "nt":
        return os.path.join(directory, "Scripts", "python.exe")
    return os.path.join(directory, "bin", "python")


def ensure_venv(directory):
    """Creates the venv and installs spym unless a previous run finished doing so."""
    python = venv_python(directory)
    if os.path.exists(os.path.join(directory, READY_MARKER)) and os.path.exists(python):
        return python
    print(f"creating {directory} and installing {' '.join(PACKAGES)} ...", flush=True)
    venv.EnvBuilder(with_pip=True, clear=True).create(directory)
    subprocess.run(
        [python, "-m", "pip", "install", "--quiet", "--disable-pip-version-check", *PACKAGES],
        check=True,
    )
    with open(os.path.join(directory, READY_MARKER), "w") as marker:
        marker.write(" ".join(PACKAGES) + "\n")
    return python


def load_spym_sm4_module():
    import importlib.util

    spec = importlib.util.find_spec("spym")
    if spec is None or spec.origin is None:
        raise RuntimeError("spym is not installed in this environment")
    path = os.path.join(os.path.dirname(spec.origin), "io", "rhksm4", "_sm4.py")
    module_spec = importlib.util.spec_from_file_location("spym_rhksm4_sm4", path)
    module = importlib.util.module_from_spec(module_spec)
    module_spec.loader.exec_module(module)
    return module


def expected_array(want):
    import numpy as np

    return np.array(
        [[math.nan if v is None else v for v in row] for row in want["data"]], dtype=np.float64
    )


def compare(where, values, want, problems, reader):
    """Appends a problem if `values` (display orientation) differ from the expectation."""
    import numpy as np

    target = expected_array(want)
    if values.shape != target.shape:
        problems.append(f"{where}: {reader} data shape {values.shape}, expected {target.shape}")
        return
    missing = np.isnan(target)
    error = np.abs(values - target)
    worst = float(np.max(error[~missing])) if np.any(~missing) else 0.0
    if worst > want["tolerance"]:
        row, column = np.unravel_index(np.argmax(np.where(missing, -1.0, error)), target.shape)
        problems.append(
            f"{where}: {reader} differs by {worst:.3e} at row {row}, column {column} "
            f"(tolerance {want['tolerance']:.3e})"
        )
    print(f"{reader} {where}: {target.shape[1]} x {target.shape[0]} px, largest difference "
          f"{worst:.3e} (tolerance {want['tolerance']:.3e})")


def check_gwyddion(sm4_path, expected, problems):
    """Converts with Gwyddion and compares its images; returns False if Gwyddion is absent."""
    import shutil
    import tempfile

    import numpy as np

    gwyddion = shutil.which("gwyddion")
    if gwyddion is None:
        print("gwyddion: not installed, stage skipped")
        return False
    import gwyfile

    with tempfile.TemporaryDirectory() as directory:
        gwy_path = os.path.join(directory, "converted.gwy")
        run = subprocess.run(
            [gwyddion, "--no-splash", f"--convert-to-gwy={gwy_path}", sm4_path],
            capture_output=True, text=True, timeout=300,
        )
        if run.returncode != 0 or not os.path.exists(gwy_path):
            problems.append(f"gwyddion could not convert the file: {run.stdout}{run.stderr}")
            return True
        container = gwyfile.load(gwy_path)
    numbers = sorted(
        int(key.split("/")[1])
        for key in container.keys()
        if key.count("/") == 2 and key.endswith("/data") and key.split("/")[1].isdigit()
    )
    if len(numbers) != len(expected["pages"]):
        problems.append(f"gwyddion found {len(numbers)} images, expected {len(expected['pages'])}")
    for number, want in zip(numbers, expected["pages"]):
        field = container[f"/{number}/data"]
        where = f"page {number} ({want['label']})"
        values = np.asarray(field["data"], dtype=np.float64).reshape(field["yres"], field["xres"])
        for axis, real, count, scale in [("x", "xreal", "columns", "x_scale"), ("y", "yreal", "rows", "y_scale")]:
            if not close(float(field[real]), want[count] * abs(want[scale])):
                problems.append(f"{where}: gwyddion {axis} size {field[real]!r}")
        compare(where, values, want, problems, "gwyddion")
    return True


def close(a, b, relative=1e-6):
    return abs(a - b) <= relative * max(abs(a), abs(b))


def check(sm4_path, expected_path):
    import warnings

    import numpy as np

    warnings.simplefilter("ignore", RuntimeWarning)  # spym's uint16 string-count arithmetic
    sm4 = load_spym_sm4_module()
    with open(expected_path) as f:
        expected = json.load(f)
    pages = list(sm4.RHKsm4(sm4_path))
    problems = []
    if len(pages) != len(expected["pages"]):
        problems.append(f"spym found {len(pages)} pages, expected {len(expected['pages'])}")
    for number, (page, want) in enumerate(zip(pages, expected["pages"])):
        where = f"page {number} ({want['label']})"
        attrs = page.attrs
        if page.label != want["label"]:
            problems.append(f"{where}: spym label {page.label!r}")
        if attrs["RHK_PageDataType"] != 0:
            problems.append(f"{where}: spym data type {attrs['RHK_PageDataType']}, expected image")
        for key, name in [("x_scale", "RHK_Xscale"), ("y_scale", "RHK_Yscale"), ("period", "RHK_Period")]:
            if not close(float(attrs[name]), want[key]):
                problems.append(f"{where}: spym {name} {float(attrs[name])!r}, expected {want[key]!r}")
        if attrs["RHK_Zunits"] != want["z_unit"]:
            problems.append(f"{where}: spym z unit {attrs['RHK_Zunits']!r}")
        data = np.asarray(page.data, dtype=np.float64)
        values = data * float(attrs["RHK_Zscale"]) + float(attrs["RHK_Zoffset"])
        compare(where, values, want, problems, "spym")
    gwyddion_ran = check_gwyddion(sm4_path, expected, problems)
    for problem in problems:
        print("MISMATCH:", problem)
    if problems:
        return 1
    print(f"ok: spym agrees on {len(pages)} pages" + (", and so does gwyddion" if gwyddion_ran else ""))
    return 0


def main(argv):
    args = list(argv[1:])
    directory = default_venv()
    if "--venv" in args:
        at = args.index("--venv")
        if at + 1 >= len(args):
            print(__doc__)
            return 2
        directory = os.path.abspath(args[at + 1])
        del args[at : at + 2]
    if len(args) != 2:
        print(__doc__)
        return 2
    sm4_path, expected_path = (os.path.abspath(a) for a in args)
    if os.environ.get(IN_VENV_FLAG) == "1":
        return check(sm4_path, expected_path)
    try:
        python = ensure_venv(directory)
    except (OSError, subprocess.CalledProcessError) as error:
        print(f"cannot set up the spym environment in {directory}: {error}")
        return 2
    env = dict(os.environ, **{IN_VENV_FLAG: "1"})
    return subprocess.run([python, os.path.realpath(__file__), sm4_path, expected_path], env=env).returncode


if __name__ == "__main__":
    sys.exit(main(sys.argv))
