"""dhct.read and dhct.Scan: dtypes, shapes, geometry, round trips through numpy, errors."""

import numpy as np
import pytest

import dhct


def test_read_gives_float64_arrays_of_the_geometry_shape(scan):
    g = scan.geometry
    for image in (scan.trace, scan.retrace):
        assert isinstance(image, np.ndarray)
        assert image.dtype == np.float64
        assert image.shape == (g["rows"], g["columns"]) == scan.shape
        assert np.isfinite(image).all()
    assert scan.unit == "m"
    # Topography of graphite in metres: corrugation well below a nanometre.
    assert 1e-12 < np.ptp(scan.trace) < 1e-9
    assert not np.array_equal(scan.trace, scan.retrace)


def test_geometry_in_metres_and_seconds(scan):
    g = scan.geometry
    assert g["pitch_m"] == (g["pitch_x_m"], g["pitch_y_m"])
    assert g["width_m"] == pytest.approx(g["columns"] * g["pitch_x_m"])
    # 4 nm frame, 256 px; one line in one direction = columns x pixel period.
    assert g["width_m"] == pytest.approx(4e-9, rel=1e-6)
    assert g["line_time_s"] == pytest.approx(g["columns"] * g["pixel_period_s"])
    assert g["fast"] == "right" and g["slow"] == "down"
    assert g["timing_source"] == "stated" and g["scale_source"] == "stated"


def test_metadata_names_the_format_and_file(scan, example):
    meta = scan.metadata
    assert meta["format"] == "RHK SM4"
    assert meta["path"] == str(example)
    assert all(isinstance(v, str) for v in meta.values())


def test_geometry_override_when_reading(example):
    s = dhct.read(example, pitch=2e-11, pixel_period=1e-3)
    assert s.geometry["pitch_x_m"] == 2e-11
    assert s.geometry["pixel_period_s"] == 1e-3


def test_from_arrays_round_trip(scan):
    g = scan.geometry
    built = dhct.Scan.from_arrays(
        scan.trace,
        scan.retrace,
        pitch_m=g["pitch_x_m"],
        pixel_period_s=g["pixel_period_s"],
        fast="right",
        slow="down",
    )
    np.testing.assert_array_equal(built.trace, scan.trace)
    np.testing.assert_array_equal(built.retrace, scan.retrace)
    for key in ("columns", "rows", "pitch_x_m", "pitch_y_m", "pixel_period_s", "fast", "slow"):
        assert built.geometry[key] == g[key], key


def test_from_arrays_line_time_and_pitch_pair():
    z = np.zeros((8, 16))
    s = dhct.Scan.from_arrays(z, pitch_m=(1e-10, 2e-10), line_time_s=0.16)
    assert s.retrace is None
    assert s.geometry["pixel_period_s"] == pytest.approx(0.01)
    assert s.geometry["pitch_y_m"] == 2e-10
    assert s.shape == (8, 16)


@pytest.mark.parametrize(
    "kwargs, needle",
    [
        (dict(pitch_m=1e-10), "exactly one of pixel_period_s and line_time_s"),
        (dict(pitch_m=1e-10, pixel_period_s=1e-3, line_time_s=1.0), "exactly one"),
        (dict(pitch_m=1e-10, pixel_period_s=1e-3, fast="sideways"), "not a scan direction"),
        (dict(pitch_m=-1e-10, pixel_period_s=1e-3), "geometry"),
        (dict(pitch_m="big", pixel_period_s=1e-3), "pitch_m"),
    ],
)
def test_from_arrays_refuses_bad_geometry(kwargs, needle):
    with pytest.raises(dhct.OptionError, match=needle):
        dhct.Scan.from_arrays(np.zeros((4, 4)), **kwargs)


def test_from_arrays_refuses_mismatched_retrace():
    with pytest.raises(dhct.OptionError):
        dhct.Scan.from_arrays(
            np.zeros((4, 4)), np.zeros((4, 5)), pitch_m=1e-10, pixel_period_s=1e-3
        )


def test_read_errors(tmp_path, example):
    with pytest.raises(dhct.ReadError, match="cannot read"):
        dhct.read(tmp_path / "missing.sm4")
    text = tmp_path / "notes.txt"
    text.write_text("not a scan\n")
    with pytest.raises(dhct.ReadError):
        dhct.read(text)
    with pytest.raises(dhct.ReadError, match="no channel 'current-xyz'.*Topography"):
        dhct.read(example, channel="current-xyz")
    with pytest.raises(dhct.OptionError):
        dhct.read(example, pixel_period=1e30)
    # Every error is a DhctError.
    assert issubclass(dhct.ReadError, dhct.DhctError)
    assert issubclass(dhct.InputMismatchError, dhct.DhctError)


def test_channel_by_name(example):
    s = dhct.read(example, channel="topography")
    assert s.channel.lower().startswith("topo")


def test_each_image_of_a_film_is_its_own_frame(example):
    film = example.parent / "real" / "specs_aarhus_film_100nm.flm"
    frames = [dhct.read(film, channel=f"image {k} ") for k in range(1, 6)]
    assert [s.geometry["frame"] for s in frames] == [0, 1, 2, 3, 4]
    assert all(s.geometry["timing_source"] == "assumed" for s in frames)
    assert frames[0].trace.shape == (512, 512)
    assert abs(frames[0].geometry["width_m"] - 100e-9) < 1e-15
