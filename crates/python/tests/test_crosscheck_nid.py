"""dhct's Nanosurf .nid reader against NSFopen (Nanosurf's PyPI reader), on the real
MIT-licensed files in tests/data/real.

NSFopen returns the data sets in storage order. Nanosurf stores the bottom line first and
every line left to right, for forward and backward alike (Gwyddion's import flips the
rows and nothing else, and the header's CurLine agrees), so dhct's images must equal the
reference flipped top to bottom, and must not equal it unflipped."""

import numpy as np
import pytest
from crosscheck import REAL, assert_differs, assert_same_values, assert_size
from NSFopen.read import read as nsf_read

import dhct


@pytest.mark.parametrize("name", ["nanosurf_afm_7um.nid", "nanosurf_grid_3um.nid"])
@pytest.mark.parametrize("channel", ["Z-Axis", "Amplitude", "Phase"])
def test_nid_matches_nsfopen(name, channel):
    ref = nsf_read(str(REAL / name))
    scan = dhct.read(REAL / name, channel=channel)
    forward = np.asarray(ref.data["Image"]["Forward"][channel], dtype=float)
    backward = np.asarray(ref.data["Image"]["Backward"][channel], dtype=float)
    assert_same_values(scan.trace, np.flipud(forward), f"{name} {channel} forward")
    assert_same_values(scan.retrace, np.flipud(backward), f"{name} {channel} backward")
    assert_differs(scan.trace, forward, f"{name}: orientation is tested")
    index = list(ref.data["Image"]["Forward"].index).index(channel)
    their_unit = ref.param["Z"]["units"][index]
    assert scan.unit == {"m": "m", "V": "V"}.get(their_unit, "deg"), their_unit
    rows, columns = forward.shape
    width = ref.param["X"]["range"][index]
    height = ref.param["Y"]["range"][index]
    assert_size(scan.geometry, width, height, columns, rows)
    line_time = ref.param["Scan"]["time/line"]["Value"][0]
    assert abs(scan.geometry["line_time_s"] / line_time - 1) < 1e-6
    assert scan.geometry["timing_source"] == "stated"
    assert scan.geometry["fast"] == "right"
