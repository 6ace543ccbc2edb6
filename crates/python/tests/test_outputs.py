"""Outputs read by tools we did not write: the corrected TIFF through tifffile."""

import subprocess

import numpy as np
import pytest

tifffile = pytest.importorskip("tifffile")


def gsf_pixel_size(path):
    """(x, y) metres per pixel from a GSF header (XReal / XRes)."""
    text = path.read_bytes().split(b"\0", 1)[0].decode("utf-8")
    header = dict(
        (k.strip(), v.strip())
        for k, v in (line.split("=", 1) for line in text.splitlines()[1:] if "=" in line)
    )
    assert header["XYUnits"] == "m"
    return (
        float(header["XReal"]) / int(header["XRes"]),
        float(header["YReal"]) / int(header["YRes"]),
    )


def test_corrected_tiff_has_the_gsf_pixel_size(cli, example, tmp_path):
    out = tmp_path / "out"
    run = subprocess.run(
        [str(cli), "correct", str(example), "-o", str(out), "--quiet"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert run.returncode == 0, run.stderr
    expected = gsf_pixel_size(out / "corrected_trace.gsf")
    with tifffile.TiffFile(out / "corrected_trace.tiff") as tif:
        page = tif.pages[0]
        assert page.dtype == np.float32
        tags = page.tags
        assert tags["ResolutionUnit"].value == 3  # centimetre
        per_cm = [n / d for n, d in (tags["XResolution"].value, tags["YResolution"].value)]
        metres = [0.01 / r for r in per_cm]
        assert metres == pytest.approx(expected, rel=1e-6)
        # ImageJ's header (what Fiji and napari read) says the same in micrometres.
        imagej = tif.imagej_metadata
        assert imagej is not None and imagej["unit"] == "um"
        micrometres_per_pixel = 1e4 / per_cm[0]  # how ImageJ converts cm with unit=um
        assert micrometres_per_pixel * 1e-6 == pytest.approx(expected[0], rel=1e-6)
        image = page.asarray()
    assert image.shape == (256, 256)
    assert np.isfinite(image).mean() > 0.9
