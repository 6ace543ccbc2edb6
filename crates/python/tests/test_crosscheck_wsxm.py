"""WSxM: dhct against SciFiReaders' `WSxM2DReader` (pycroscopy).

SciFiReaders returns a sidpy dataset indexed (x, y) with y decreasing along its second
axis, so its transpose is in display orientation (row 0 at the top). It scales the stored
values by Z Amplitude over the header's Maximum - Minimum; for the int16 `.top` files those
are the data's own extremes, as dhct (and Gwyddion) use, so the values must agree. The
`.stp` copy stores doubles whose header Maximum/Minimum belong to the int16 version, so
there only the shape of the values (each image divided by its range) is compared.
"""

from pathlib import Path

import numpy as np
import pytest

import dhct

sr = pytest.importorskip("SciFiReaders")

REAL = Path(__file__).resolve().parents[3] / "tests" / "data" / "real"
LENGTH = {"nm": 1e-9, "µm": 1e-6, "Å": 1e-10, "pm": 1e-12}


def reference(path):
    datasets = sr.WSxM2DReader(str(path)).read()
    assert len(datasets) == 1
    return next(iter(datasets.values()))


@pytest.mark.parametrize(
    "name", ["wsxm_jumpingmode_topography_15um.top", "wsxm_topography_600nm.top"]
)
def test_int16_images_match_in_size_orientation_and_value(name):
    path = REAL / name
    theirs = reference(path)
    scan = dhct.read(path)
    g = scan.geometry
    image = np.asarray(theirs).T
    assert scan.trace.shape == image.shape == (g["rows"], g["columns"]) == (256, 256)
    x, y = theirs._axes[0], theirs._axes[1]
    assert g["width_m"] == pytest.approx(float(np.ptp(np.asarray(x))) * LENGTH[x.units], rel=1e-3)
    assert g["height_m"] == pytest.approx(float(np.ptp(np.asarray(y))) * LENGTH[y.units], rel=1e-3)
    assert scan.channel == theirs.quantity == "Topography"
    np.testing.assert_allclose(scan.trace, image * LENGTH[theirs.units], rtol=1e-6, atol=0)
    # The check can fail: the untransposed or mirrored data differ.
    assert not np.allclose(scan.trace, np.asarray(theirs) * LENGTH[theirs.units], rtol=1e-6, atol=0)
    assert not np.allclose(scan.trace, image[::-1] * LENGTH[theirs.units], rtol=1e-6, atol=0)


def test_the_double_image_matches_up_to_the_header_range_scale():
    path = REAL / "wsxm_topography_600nm.stp"
    image = np.asarray(reference(path)).T
    scan = dhct.read(path)
    assert scan.trace.shape == image.shape
    ours = (scan.trace - scan.trace.min()) / np.ptp(scan.trace)
    theirs = (image - image.min()) / np.ptp(image)
    np.testing.assert_allclose(ours, theirs, rtol=1e-6, atol=1e-9)
    # dhct spans exactly the Z Amplitude of the header, 13.7008 nm.
    assert np.ptp(scan.trace) == pytest.approx(13.7008e-9, rel=1e-9)
