"""Createc .dat: dhct against the `createc` package (Createc's own Python interface).

The `createc` reader assumes the zlib data start at byte 16 384, as in files written by the
Createc software; the repository's real file has a shortened header (its DATA line is at
byte 16 268), so both readers are given a copy whose header is padded with a line of spaces
up to that offset. `createc` returns the stored counts; dhct's values are compared with
them times the calibration dhct documents (Z: 20 V / 2^bits x ZPiezoconst x GainZ;
current: 20 V / 2^bits / 10^GainPre), with the header fields as `createc` parsed them.
"""

from pathlib import Path

import numpy as np
import pytest

import dhct

createc_file = pytest.importorskip("createc.Createc_pyFile")

REAL = Path(__file__).resolve().parents[3] / "tests" / "data" / "real" / "createc_atomic_11nm.dat"
OFFSET = 16384


@pytest.fixture(scope="module")
def padded(tmp_path_factory):
    raw = REAL.read_bytes()
    data_line = raw.index(b"\nDATA") + 1
    pad = OFFSET - (data_line + 4)
    assert pad > 2, "the real file's header is already full length"
    padded = raw[:data_line] + b" " * (pad - 2) + b"\r\n" + raw[data_line:]
    assert padded.index(b"\nDATA") + 5 == OFFSET
    path = tmp_path_factory.mktemp("createc") / "padded.dat"
    path.write_bytes(padded)
    return path


@pytest.fixture(scope="module")
def reference(padded):
    return createc_file.DAT_IMG(str(padded))


def test_padding_changes_nothing_dhct_reads(padded):
    for channel in ("Z", "Current"):
        a, b = dhct.read(REAL, channel), dhct.read(padded, channel)
        np.testing.assert_array_equal(a.trace, b.trace)
        np.testing.assert_array_equal(a.retrace, b.retrace)


def test_dims_and_physical_size_match(padded, reference):
    scan = dhct.read(padded)
    g = scan.geometry
    assert (g["columns"], g["rows"]) == (reference.xPixel, reference.yPixel) == (512, 512)
    assert scan.trace.shape == reference.imgs[0].shape
    size = reference.nom_size  # angstrom
    assert g["width_m"] == pytest.approx(size.x * 1e-10, rel=1e-3)
    assert g["height_m"] == pytest.approx(size.y * 1e-10, rel=1e-3)
    assert len(reference.imgs) == reference.channels == 4


def test_values_match_the_stored_counts_times_the_calibration(padded, reference):
    meta = reference.meta
    bits = int(meta["dac-type"].strip().rstrip("bit"))
    volts = 20.0 / 2**bits
    z_per_count = volts * float(meta["zpiezoconst"]) * float(meta["gainz"]) * 1e-10
    i_per_count = volts / 10 ** float(meta["gainpre 10^"])
    # createc's order: Z forward, current forward, Z backward, current backward.
    z, current = dhct.read(padded, "z"), dhct.read(padded, "current")
    pairs = [
        (z.trace, reference.imgs[0], z_per_count),
        (current.trace, reference.imgs[1], i_per_count),
        (z.retrace, reference.imgs[2], z_per_count),
        (current.retrace, reference.imgs[3], i_per_count),
    ]
    for ours, counts, factor in pairs:
        expected = counts.astype(np.float64) * factor
        np.testing.assert_allclose(ours, expected, rtol=1e-6, atol=0)
    # The comparison can fail: the same data mirrored or shifted by one value differ.
    assert not np.allclose(z.trace, reference.imgs[0][:, ::-1] * z_per_count, rtol=1e-6, atol=0)
    assert not np.allclose(z.trace, reference.imgs[2] * z_per_count, rtol=1e-6, atol=0)
