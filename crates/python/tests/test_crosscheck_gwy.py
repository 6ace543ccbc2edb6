"""dhct's .gwy reader against gwyfile (PyPI), on the real files in tests/data/real."""

import gwyfile
import numpy as np
import pytest
from crosscheck import REAL, assert_differs, assert_same_values, assert_size

import dhct


def fields(path):
    return gwyfile.util.get_datafields(gwyfile.load(str(path)))


@pytest.mark.parametrize(
    "name, channel, forward, backward",
    [
        ("moire_4K_10nm.gwy", "Z", "Z (Forward)", "Z (Backward)"),
        ("moire_4K_10nm.gwy", "Current", "Current (Forward)", "Current (Backward)"),
        ("gwyfile_test.gwy", "Test", "Test", None),
    ],
)
def test_gwy_matches_gwyfile(name, channel, forward, backward):
    path = REAL / name
    theirs = fields(path)
    scan = dhct.read(path, channel=channel)
    ref = theirs[forward]
    # Gwyddion and gwyfile keep images in display orientation: row 0 at the top.
    assert_same_values(scan.trace, ref.data, f"{name} {forward}")
    assert_differs(scan.trace, np.flipud(ref.data), f"{name}: orientation is tested")
    assert scan.unit == ref["si_unit_z"]["unitstr"]
    if backward is None:
        assert scan.retrace is None
        assert scan.geometry["scale_source"] == "assumed"  # 1 m pixels are not a scan
    else:
        assert_same_values(scan.retrace, theirs[backward].data, f"{name} {backward}")
        assert ref["si_unit_xy"]["unitstr"] == "m"
        assert_size(scan.geometry, ref["xreal"], ref["yreal"], ref["xres"], ref["yres"])
    assert scan.geometry["timing_source"] == "assumed"
