#!/usr/bin/env python3
"""dhct series against SPmerge (Ophus et al. 2016; its Python port scanning_drift_corr) on
the same simulated 0°/90° pair, accuracy and time in one run.

Usage (after `cargo build --release -p dhct-cli`):
    python3 scripts/peers/spmerge_pair.py [--size 256] [--json OUT.json]

For each variant (the graphite-sequence preset cut to two frames at 0° and 90°: with its
fast-scan hysteresis, and without), the pair is simulated with `dhct simulate`, registered
by `dhct series` and merged by SPmerge01linear + SPmerge02 + SPmerge03 (the package's own
example settings, 32 and 8 refinement steps, both scan angle signs tried and the better
kept). Both are given the two trace images only where a peer needs images (SPmerge) and
the files (dhct).

Both outputs are judged the same way, from the images alone, as an outsider would: the
atoms of the output image are found (local maxima, sub-pixel by a quadratic through 3 x 3
pixels) and one lattice `o + n a1 + m a2` is fitted to them. The rms of the atoms about it
is what no affine map explains (local distortion left), in pm and pixels; the fitted
lattice's constants and angle against the simulator's (graphite, 2.46 Å, 60°) are what an
affine map would still have to fix (scale, shear). dhct's image is the mean of its two
registered traces (the same data SPmerge merges); the raw first trace is scored too.

Packages (numpy, scipy, h5py, matplotlib, tqdm, scanning_drift_corr) are installed with pip
into target/tmp/spmerge-venv, and the script runs itself again under it.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import venv

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, "..", ".."))
VENV = os.path.join(ROOT, "target", "tmp", "spmerge-venv")
PACKAGES = ["numpy", "scipy", "h5py", "matplotlib", "tqdm", "scanning_drift_corr"]
DHCT = os.path.join(ROOT, "target", "release", "dhct")
A_M = 2.46e-10


def ensure_venv():
    python = os.path.join(VENV, "bin", "python")
    if not os.path.exists(python):
        venv.EnvBuilder(with_pip=True).create(VENV)
    probe = subprocess.run([python, "-c", "import scanning_drift_corr.api, scipy"],
                           capture_output=True)
    if probe.returncode != 0:
        subprocess.run([python, "-m", "pip", "install", "-q", *PACKAGES], check=True)
    return python


def config_text(size, hysteresis):
    """The graphite-sequence preset cut to a 0°/90° pair, `size` px over size/64 nm."""
    width = size / 64.0 * 1e-9
    effects = ("[[effects]]\nkind = \"fast-hysteresis\"\n"
               "law = { kind = \"power\", k = 0.95, n = -0.03 }\n") if hysteresis else ""
    return f"""
name = "pair"
seed = 3
[scan]
columns = {size}
rows = {size}
width_m = {width:e}
height_m = {width:e}
fast_speed_m_per_s = {50e-9 * size / 256:e}
trace_fast = "right"
slow = "down"
[surface]
lattice = {{ kind = "graphite" }}
feature = {{ height_m = 40e-12, sigma_m = [0.6e-10, 0.6e-10] }}
[noise]
white_sigma_m = 2e-12
{effects}
[output]
formats = ["sm4", "npy"]
[sequence]
frames = 2
pause_s = 3.0
scan_angles_deg = [0.0, 90.0]
drift = {{ velocity_m_per_s = [3e-12, -2e-12], acceleration_m_per_s2 = [1e-15, 0.0], oscillation_m = [2e-10, 1e-10], oscillation_period_s = 260.0 }}
initial_creep = {{ coefficient_m = [1e-10, 5e-11], t0_s = 20.0 }}
"""


def read_gsf(path):
    """A Gwyddion Simple Field: (image as rows x columns, metres per pixel x)."""
    import numpy as np
    data = open(path, "rb").read()
    header_end = data.index(b"\0")
    header = data[:header_end].decode("utf-8").splitlines()
    fields = dict(line.split("=", 1) for line in header[1:] if "=" in line)
    fields = {k.strip(): v.strip() for k, v in fields.items()}
    xres, yres = int(fields["XRes"]), int(fields["YRes"])
    start = header_end + (4 - header_end % 4)
    z = np.frombuffer(data[start:start + 4 * xres * yres], dtype="<f4").reshape(yres, xres)
    return z.astype(float), float(fields["XReal"]) / xres


def atoms(image, a_px):
    """Sub-pixel local maxima of `image` (NaN where no data) at least 0.6 periods apart,
    away from the edges and missing data."""
    import numpy as np
    from scipy import ndimage
    valid = np.isfinite(image)
    filled = np.where(valid, image, np.nanmedian(image))
    smooth = ndimage.gaussian_filter(filled - ndimage.gaussian_filter(filled, 2 * a_px),
                                     0.15 * a_px)
    size = max(3, int(round(0.6 * a_px)))
    peaks = (smooth == ndimage.maximum_filter(smooth, size=size))
    peaks &= smooth > np.percentile(smooth, 60)
    margin = int(np.ceil(a_px))
    keep = ndimage.binary_erosion(valid, iterations=margin, border_value=0)
    rows, cols = np.nonzero(peaks & keep)
    points = []
    for r, c in zip(rows, cols):
        patch = smooth[r - 1:r + 2, c - 1:c + 2]
        dx = 0.5 * (patch[1, 0] - patch[1, 2]) / (patch[1, 0] - 2 * patch[1, 1] + patch[1, 2])
        dy = 0.5 * (patch[0, 1] - patch[2, 1]) / (patch[0, 1] - 2 * patch[1, 1] + patch[2, 1])
        if abs(dx) <= 0.5 and abs(dy) <= 0.5:
            points.append((c + dx, r + dy))
    return np.array(points)


def lattice_fit(points, a_px):
    """One lattice o + n a1 + m a2 fitted to `points` (px): returns (rms px, |a1|, |a2|
    px, angle degrees, atoms used). The basis starts from the nearest-neighbour vectors."""
    import numpy as np
    from scipy.spatial import cKDTree
    tree = cKDTree(points)
    _, idx = tree.query(points, k=7)
    vectors = (points[idx[:, 1:]] - points[:, None, :]).reshape(-1, 2)
    lengths = np.hypot(vectors[:, 0], vectors[:, 1])
    vectors = vectors[(lengths > 0.7 * a_px) & (lengths < 1.3 * a_px)]
    angles = np.degrees(np.arctan2(vectors[:, 1], vectors[:, 0])) % 180.0
    # The basis: the most common direction, and the one 60 degrees from it.
    histogram, edges = np.histogram(angles % 60.0, bins=60, range=(0, 60))
    base = edges[np.argmax(histogram)] + 0.5
    basis = []
    for target in (base, base + 60.0):
        near = np.abs(((angles - target + 90) % 180) - 90) < 8
        chosen = vectors[near]
        chosen = np.where((chosen @ np.array([np.cos(np.radians(target)),
                                              np.sin(np.radians(target))]))[:, None] < 0,
                          -chosen, chosen)
        basis.append(np.median(chosen, axis=0))
    a = np.array(basis).T
    origin = points[len(points) // 2]
    for _ in range(4):
        frac = np.linalg.solve(a, (points - origin).T).T
        index = np.round(frac)
        design = np.column_stack([np.ones(len(points)), index])
        coef, *_ = np.linalg.lstsq(design, points, rcond=None)
        residual = points - design @ coef
        distance = np.hypot(residual[:, 0], residual[:, 1])
        inliers = distance < 0.35 * a_px
        coef, *_ = np.linalg.lstsq(design[inliers], points[inliers], rcond=None)
        origin, a = coef[0], coef[1:].T
    residual = (points - design @ coef)[inliers]
    rms = float(np.sqrt(np.mean(np.sum(residual ** 2, axis=1))))
    a1, a2 = a[:, 0], a[:, 1]
    angle = float(np.degrees(np.arccos(a1 @ a2 / np.hypot(*a1) / np.hypot(*a2))))
    return rms, float(np.hypot(*a1)), float(np.hypot(*a2)), angle, int(inliers.sum())


def judge(name, image, pitch_m):
    a_px = A_M / pitch_m
    points = atoms(image, a_px)
    rms, a1, a2, angle, used = lattice_fit(points, a_px)
    row = {
        "method": name,
        "atoms": used,
        "rms_about_lattice_pm": rms * pitch_m * 1e12,
        "rms_about_lattice_px": rms,
        "a1_pm": a1 * pitch_m * 1e12,
        "a2_pm": a2 * pitch_m * 1e12,
        "angle_deg": angle if angle < 90 else 180 - angle,
    }
    print(f"  {name:<34} {used:>5} atoms, rms about one lattice {row['rms_about_lattice_pm']:6.2f} pm "
          f"({rms:.3f} px); a = {row['a1_pm']:.1f} x {row['a2_pm']:.1f} pm at {row['angle_deg']:.2f}°"
          " (truth 246.0 x 246.0 pm at 60°)")
    return row


def run_spmerge(python, traces, work):
    """SPmerge on the two traces with scan angles (0, s·90); returns (image, seconds)."""
    import numpy as np
    script = os.path.join(work, "spmerge_run.py")
    np.save(os.path.join(work, "in0.npy"), traces[0])
    np.save(os.path.join(work, "in1.npy"), traces[1])
    with open(script, "w") as f:
        f.write("""
import sys, time, numpy as np
import scanning_drift_corr.api as sdc
work, angle = sys.argv[1], float(sys.argv[2])
a, b = np.load(work + '/in0.npy'), np.load(work + '/in1.npy')
t = time.perf_counter()
sm = sdc.SPmerge01linear((0, angle), a, b, flagPlot=False, flagReportProgress=False)
sm = sdc.SPmerge02(sm, 32, 8, flagPlot=False, flagReportProgress=False)
image, signal, density = sdc.SPmerge03(sm, flagPlot=False, flagReportProgress=False)
seconds = time.perf_counter() - t
density = density.reshape(-1, *image.shape[-2:]).sum(axis=0)
image = np.where(density > 1.0, image.reshape(density.shape), np.nan)
np.save(work + '/out.npy', image)
print(seconds)
""")
    results = {}
    for angle in (90.0, -90.0):
        run = subprocess.run([python, script, work, str(angle)], capture_output=True, text=True,
                             env=dict(os.environ, MPLBACKEND="Agg", PYTHONWARNINGS="ignore"))
        if run.returncode != 0:
            print(f"  SPmerge at (0, {angle:+.0f})° failed: {run.stderr.strip().splitlines()[-1:]}")
            continue
        results[angle] = (np.load(os.path.join(work, "out.npy")),
                          float(run.stdout.strip().splitlines()[-1]))
    return results


def variant(python, size, hysteresis, work):
    import numpy as np
    label = "with fast-scan hysteresis" if hysteresis else "no hysteresis"
    print(f"\n## 0°/90° pair, {size}², graphite, drift and creep, {label}")
    config = os.path.join(work, "pair.toml")
    with open(config, "w") as f:
        f.write(config_text(size, hysteresis))
    frames = os.path.join(work, "frames")
    subprocess.run([DHCT, "simulate", config, "-o", frames], check=True, capture_output=True)
    out = os.path.join(work, "dhct")
    t = time.perf_counter()
    series = subprocess.run([DHCT, "series", os.path.join(frames, "*.sm4"), "-o", out,
                             "--quiet"], capture_output=True, text=True)
    dhct_seconds = time.perf_counter() - t
    rows = []
    pitch = size / 64.0 * 1e-9 / size
    raw = np.load(os.path.join(frames, "frame_00_trace.npy"))
    rows.append(judge("raw first trace", raw, pitch))
    if series.returncode != 0:
        print(f"  dhct series failed: {series.stderr.strip()}")
    else:
        z0, _ = read_gsf(os.path.join(out, "registered", "frame_00_trace.gsf"))
        z1, _ = read_gsf(os.path.join(out, "registered", "frame_01_trace.gsf"))
        z1 = z1 - np.nanmedian(z1 - z0)
        both = np.isfinite(z0) & np.isfinite(z1)
        mean = np.where(both, 0.5 * (z0 + z1), np.nan)
        row = judge("dhct series (mean of 2 traces)", mean, pitch)
        row["seconds"] = dhct_seconds
        rows.append(row)
        print(f"  dhct series: {dhct_seconds:.2f} s (both frames' analyses, the fit, every "
              "output)")
    traces = [np.load(os.path.join(frames, f"frame_0{k}_trace.npy")) for k in (0, 1)]
    merged = run_spmerge(python, traces, work)
    for angle, (image, seconds) in merged.items():
        row = judge(f"SPmerge (0, {angle:+.0f})°", image, pitch)
        row["seconds"] = seconds
        rows.append(row)
        print(f"  SPmerge (0, {angle:+.0f})°: {seconds:.2f} s")
    return {"variant": label, "size": size, "rows": rows}


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--json")
    args = parser.parse_args()
    if not os.path.exists(DHCT):
        sys.exit(f"{DHCT} not found: run `cargo build --release -p dhct-cli` first")
    python = ensure_venv()
    if os.path.realpath(sys.prefix) != os.path.realpath(VENV):
        # Scored with the venv's numpy and scipy.
        os.execv(python, [python, os.path.abspath(__file__), *sys.argv[1:]])
    report = []
    for hysteresis in (False, True):
        with tempfile.TemporaryDirectory() as work:
            report.append(variant(python, args.size, hysteresis, work))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(report, f, indent=1)


if __name__ == "__main__":
    main()
