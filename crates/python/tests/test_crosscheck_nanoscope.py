"""dhct's Bruker Nanoscope reader against pySPM (PyPI), on Bruker's example file in
tests/data/real.

pySPM returns the stored lines in storage order (bottom line first; Gwyddion's import
flips them), in nm, so dhct's images must equal the reference flipped top to bottom and
scaled to metres. (pySPM needs the scan size in the image section, so the older
nanoscope_d3100_2um.000 is checked in the Rust tests only.)"""

import warnings

import numpy as np
import pytest
from crosscheck import REAL, assert_differs, assert_same_values, assert_size

import dhct

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    import pySPM

PATH = REAL / "bruker_example_40um.spm"
UNITS = {"nm": 1e-9, "um": 1e-6, "V": 1.0, "mV": 1e-3}


@pytest.mark.parametrize(
    "channel, ours, backward",
    [("Height", "Height", False), ("Friction", "Friction", True)],
)
def test_nanoscope_matches_pyspm(channel, ours, backward):
    image = pySPM.Bruker(str(PATH)).get_channel(channel, backward=backward, lazy=False)
    scan = dhct.read(PATH, channel=ours)
    ref = np.asarray(image.pixels, dtype=float) * UNITS[image.zscale]
    mine = scan.retrace if backward else scan.trace
    assert_same_values(mine, np.flipud(ref), f"{channel}")
    assert_differs(mine, ref, "orientation is tested")
    assert scan.unit == {"nm": "m", "um": "m", "V": "V", "mV": "V"}[image.zscale]
    real = image.size["real"]
    factor = UNITS[real["unit"]]
    rows, columns = ref.shape
    assert_size(scan.geometry, real["x"] * factor, real["y"] * factor, columns, rows)
    assert scan.geometry["fast"] == "right"
