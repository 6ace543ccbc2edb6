"""Helpers for comparing dhct's readers with independent readers (the test_crosscheck_*
files)."""

from pathlib import Path

import numpy as np

REAL = Path(__file__).resolve().parents[3] / "tests" / "data" / "real"

#: Relative tolerance of values, and of sizes (0.1 %).
VALUE_RTOL = 1e-6
SIZE_RTOL = 1e-3


def assert_same_values(ours, theirs, what):
    """Equal to VALUE_RTOL of the reference's largest magnitude (so values near zero are
    compared on the image's own scale)."""
    ours, theirs = np.asarray(ours), np.asarray(theirs)
    assert ours.shape == theirs.shape, f"{what}: shape {ours.shape} vs {theirs.shape}"
    scale = np.nanmax(np.abs(theirs))
    assert scale > 0, f"{what}: the reference image is all zero"
    np.testing.assert_allclose(
        ours, theirs, rtol=VALUE_RTOL, atol=VALUE_RTOL * scale, err_msg=what
    )


def assert_differs(ours, theirs, what):
    """The comparison must be able to fail: `theirs` (e.g. the unflipped reference) must
    not match."""
    scale = np.nanmax(np.abs(theirs))
    assert not np.allclose(ours, theirs, rtol=VALUE_RTOL, atol=VALUE_RTOL * scale), what


def assert_size(geometry, width_m, height_m, columns, rows):
    assert (geometry["columns"], geometry["rows"]) == (columns, rows)
    assert abs(geometry["width_m"] / width_m - 1) < SIZE_RTOL, geometry["width_m"]
    assert abs(geometry["height_m"] / height_m - 1) < SIZE_RTOL, geometry["height_m"]
