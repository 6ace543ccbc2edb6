"""Omicron MATRIX: dhct against `access2thematrix` (the maintained MATRIX reader).

access2thematrix returns each image with its first row at the bottom (row 0 = the first
line of an upward scan), so it is flipped upside down to compare with dhct's display
orientation (row 0 at the top).
"""

from pathlib import Path

import numpy as np
import pytest

import dhct

access2thematrix = pytest.importorskip("access2thematrix")

REAL = Path(__file__).resolve().parents[3] / "tests" / "data" / "real"
DATA = REAL / "20201111--4_1.Z_mtrx"


@pytest.fixture(scope="module")
def reference():
    mtrx = access2thematrix.MtrxData()
    traces, message = mtrx.open(str(DATA))
    assert "Successfully" in message, message
    return mtrx, traces


def test_directions_dims_size_and_values_match(reference):
    mtrx, traces = reference
    assert sorted(traces.values()) == ["backward/up", "forward/up"]
    scan = dhct.read(DATA)
    g = scan.geometry
    assert scan.channel == "Z" and scan.unit == "m"
    assert g["slow"] == "up" and g["fast"] == "right"
    for name, ours in (("forward/up", scan.trace), ("backward/up", scan.retrace)):
        image, _ = mtrx.select_image(name)
        assert image.channel_name_and_unit == ["Z", "m"]
        assert ours.shape == image.data.shape == (400, 400)
        assert g["width_m"] == pytest.approx(image.width, rel=1e-3)
        assert g["height_m"] == pytest.approx(image.height, rel=1e-3)
        np.testing.assert_allclose(ours, np.flipud(image.data), rtol=1e-6, atol=0)
        # The check can fail: without the flip the images differ.
        assert not np.allclose(ours, image.data, rtol=1e-6, atol=0)
    # Raster time 0.5 ms per point, as the parameter file says.
    assert mtrx.param["EEPA::XYScanner.Raster_Time"][0] == pytest.approx(g["pixel_period_s"])


def test_a_data_file_without_its_parameter_file_is_refused_naming_it(tmp_path):
    lone = tmp_path / DATA.name
    lone.write_bytes(DATA.read_bytes())
    with pytest.raises(dhct.ReadError, match="20201111_0001.mtrx"):
        dhct.read(lone)
