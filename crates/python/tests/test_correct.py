"""dhct.correct: the same model as `dhct correct`, arrays and columns, write, errors."""

import json
from pathlib import Path
import subprocess
import threading

import numpy as np
import pytest

import dhct

REL = 1e-9


def cli_json(cli, example, tmp_path, *flags):
    """`dhct correct EXAMPLE -o DIR --json FLAGS` parsed."""
    out = tmp_path / "cli"
    run = subprocess.run(
        [str(cli), "correct", str(example), "-o", str(out), "--json", *flags],
        capture_output=True,
        text=True,
        check=False,
    )
    assert run.returncode == 0, run.stderr
    return json.loads(run.stdout), out


def assert_same_parameters(a, b):
    assert [p["name"] for p in a] == [p["name"] for p in b]
    for p, q in zip(a, b):
        assert p["unit"] == q["unit"] and p["determined"] == q["determined"], p["name"]
        assert p["value"] == pytest.approx(q["value"], rel=REL, abs=0), p["name"]
        if q["sigma"] is None:
            assert p["sigma"] is None, p["name"]
        else:
            assert p["sigma"] == pytest.approx(q["sigma"], rel=REL, abs=0), p["name"]


def test_same_model_as_the_command_line(cli, example, result, tmp_path):
    expected, _ = cli_json(cli, example, tmp_path)
    model = result.model
    assert_same_parameters(model["parameters"], expected["parameters"])
    assert model["passes"] == expected["passes"]
    assert model["lattice"] == expected["lattice"] == "graphite"
    assert [w["code"] for w in model["warnings"]] == [w["code"] for w in expected["warnings"]]
    for mine, theirs in zip(model["regions"], expected["regions"]):
        assert mine["lattice_constant_m"] == pytest.approx(theirs["lattice_constant_m"], rel=REL)


def test_path_input_and_array_input_agree(example, scan, result):
    from_path = dhct.correct(example)
    assert_same_parameters(from_path.model["parameters"], result.model["parameters"])
    g = scan.geometry
    built = dhct.Scan.from_arrays(
        scan.trace, scan.retrace, pitch_m=g["pitch_x_m"], pixel_period_s=g["pixel_period_s"]
    )
    from_arrays = dhct.correct(built)
    assert_same_parameters(from_arrays.model["parameters"], result.model["parameters"])
    assert from_arrays.model["input"] == "<arrays>"


def test_same_options_same_model_as_the_command_line(cli, example, tmp_path):
    expected, _ = cli_json(cli, example, tmp_path, "--nn", "2.46A", "--polarity", "bright")
    mine = dhct.correct(example, nn="2.46A", polarity="bright")
    assert_same_parameters(mine.model["parameters"], expected["parameters"])
    assert mine.model["nearest_neighbour_distance_m"] == expected["nearest_neighbour_distance_m"]


def test_corrected_images_have_the_scan_shape(scan, result):
    for image in (result.corrected_trace, result.corrected_retrace):
        assert image.dtype == np.float64
        assert image.shape == scan.shape
        assert np.isfinite(image).mean() > 0.5
    # Corrected, not a copy of the raw image.
    assert not np.array_equal(np.nan_to_num(result.corrected_trace), scan.trace)


def test_feature_columns_equal_length_positions_in_metres(scan, result):
    f = result.features
    lengths = {name: len(values) for name, values in f.items()}
    n = sum(p["features"] for p in result.model["passes"])
    assert set(lengths.values()) == {n}, lengths
    assert f["x_m"].dtype == np.float64 and f["id"].dtype == np.int64
    assert f["indexed"].dtype == np.bool_
    pitch = scan.geometry["pitch_x_m"]
    np.testing.assert_allclose(f["x_m"], f["x_px"] * pitch, rtol=0, atol=pitch)
    assert set(f["pass"]) == {"trace", "retrace"}
    indexed = f["indexed"]
    assert indexed.sum() == sum(p["indexed"] for p in result.model["passes"])
    assert (f["region"][~indexed] == -1).all() and np.isnan(f["deviation_x_m"][~indexed]).all()
    # Deviations from the fitted lattice: picometres, not nanometres.
    assert np.nanmax(np.abs(f["deviation_x_m"])) < 5e-11


def test_feature_columns_match_features_csv(result, tmp_path):
    result.write(tmp_path / "out")
    header = (tmp_path / "out" / "features.csv").read_text().splitlines()[0].split(",")
    columns = list(result.features)
    assert [c for c in columns if c != "indexed"] == header


def test_features_frame(result):
    pd = pytest.importorskip("pandas")
    frame = result.features_frame()
    assert isinstance(frame, pd.DataFrame)
    assert list(frame.columns) == list(result.features)
    assert len(frame) == len(result.features["x_m"])


def test_lattice_unit_cell_and_warnings(result):
    lattice = result.lattice
    assert lattice["primitive_vectors_m"].shape == (2, 2)
    assert lattice["nearest_neighbour_distance_m"] == pytest.approx(2.46e-10, rel=1e-6)  # graphite: the β sites
    assert lattice["regions"] and lattice["regions"][0]["lattice_constant_m"][0] > 0
    cell = result.unit_cell
    assert cell["averaged"].ndim == 2 and cell["averaged"].dtype == np.float64
    assert cell["symmetrized"].shape == cell["averaged"].shape
    assert cell["cells_selected"] <= cell["cells_available"]
    assert {w["code"] for w in result.warnings} <= {
        w["code"] for w in result.model["warnings"]
    }
    assert set(result.parameters) == {p["name"] for p in result.model["parameters"]}
    assert result.calibration is not None


def test_write_gives_the_command_lines_files(cli, example, result, tmp_path):
    _, cli_out = cli_json(cli, example, tmp_path)
    written = result.write(tmp_path / "py")
    mine = sorted(p.name for p in (tmp_path / "py").iterdir())
    theirs = sorted(p.name for p in cli_out.iterdir())
    assert mine == theirs
    assert sorted(written["outputs"]) == sorted(
        json.loads((cli_out / "model.json").read_text())["outputs"]
    )
    on_disk = json.loads((tmp_path / "py" / "model.json").read_text())
    assert_same_parameters(on_disk["parameters"], result.model["parameters"])
    with pytest.raises(dhct.WriteError, match="overwrite"):
        result.write(tmp_path / "py")
    result.write(tmp_path / "py", overwrite=True)


def test_repr_html(result):
    page = result._repr_html_()
    for p in result.model["parameters"]:
        assert f"<td>{p['name']}</td>" in page
    assert "graphite" in repr(result)


def test_mask_array_limits_the_analysis(scan, result):
    rows, columns = scan.shape
    mask = np.zeros(scan.shape, dtype=bool)
    mask[:, : columns // 2] = True
    half = dhct.correct(scan, mask=mask)
    # Features are found everywhere; only those inside the mask are indexed and fitted.
    n_all = result.features["indexed"].sum()
    f = half.features
    x = f["x_px"][f["indexed"]]
    assert 0 < len(x) < 0.6 * n_all
    assert x.max() < columns / 2
    with pytest.raises(dhct.OptionError, match="2-D"):
        dhct.correct(scan, mask=np.zeros(5))
    with pytest.raises(dhct.OptionError, match="the mask is 5 x 5"):
        dhct.correct(scan, mask=np.ones((5, 5)))


def test_progress_called_for_each_stage_and_gil_released(scan):
    counter = [0]
    stop = threading.Event()

    def spin():
        while not stop.is_set():
            counter[0] += 1

    seen = []

    def progress(stage):
        seen.append((stage, counter[0]))

    thread = threading.Thread(target=spin)
    thread.start()
    try:
        dhct.correct(scan, progress=progress)
    finally:
        stop.set()
        thread.join()
    stages = [s for s, _ in seen]
    assert "finding and fitting features" in stages and len(stages) >= 4
    # Between the first and the last stage the Rust code ran without the GIL: the other
    # Python thread kept counting (with the GIL held it could not run at all).
    assert seen[-1][1] - seen[0][1] > 100


def test_progress_errors_are_raised(scan):
    def progress(stage):
        raise KeyError("from the callback")

    with pytest.raises(KeyError, match="from the callback"):
        dhct.correct(scan, progress=progress)


@pytest.mark.parametrize(
    "kwargs, error, needles",
    [
        (dict(nn="1.23A"), dhct.InputMismatchError, ["calibrate=True", "pixel size"]),
        (dict(lattice="square", nn="2.46A"), dhct.InputMismatchError, ["square lattice"]),
        (dict(lattice="square"), dhct.OptionError, ['lattice="square" needs nn=']),
        (dict(lattice="no-such-lattice"), dhct.OptionError, ["no-such-lattice"]),
        (dict(pipeline={"features": {"no_such_key": 1}}), dhct.OptionError, ["no_such_key"]),
        (dict(calibrat=True), dhct.OptionError, ["did you mean 'calibrate'"]),
        (dict(polarity="sideways"), dhct.OptionError, ["sideways"]),
        (dict(pixel_period=1e30), dhct.OptionError, ["pixel_period"]),
    ],
)
def test_errors_name_the_keyword_arguments(scan, kwargs, error, needles):
    with pytest.raises(error) as caught:
        dhct.correct(scan, **kwargs)
    for needle in needles:
        assert needle in str(caught.value)


def test_input_mismatch_says_what_the_command_line_says_with_keyword_hints(
    cli, example, tmp_path
):
    run = subprocess.run(
        [str(cli), "correct", str(example), "-o", str(tmp_path / "o"), "--nn", "1.23A"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert run.returncode == 1
    with pytest.raises(dhct.InputMismatchError) as caught:
        dhct.correct(example, nn="1.23A")
    cli_error, cli_hint = run.stderr.strip().split("\nhint: ")
    python_error, python_hint = str(caught.value).split("\nhint: ")
    # The same measurement; the hint names keyword arguments, not flags.
    assert cli_error == f"error: {python_error}"
    assert "--calibrate" in cli_hint and "--" not in python_hint
    assert 'nn="auto"' in python_hint and "calibrate=True" in python_hint
    assert "trust_inputs=True" in python_hint


def test_escape_hatches_resolve_as_the_command_line(example):
    # --nn 1.23A is refused; with --trust-inputs it runs (no check, no calibration).
    trusted = dhct.correct(example, nn="1.23A", trust_inputs=True)
    assert trusted.model["nearest_neighbour_distance_m"] == pytest.approx(1.23e-10)
    assert trusted.calibration is None


def test_read_errors_from_correct(tmp_path):
    with pytest.raises(dhct.ReadError):
        dhct.correct(tmp_path / "missing.sm4")
    with pytest.raises(dhct.OptionError):
        dhct.correct(42)


def _numbers_close(a, b, path="diagnosis"):
    """Nested JSON values equal, numbers to 1e-9 relative."""
    if isinstance(a, dict):
        assert a.keys() == b.keys(), path
        for k in a:
            _numbers_close(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            _numbers_close(x, y, f"{path}[{i}]")
    elif isinstance(a, float) and isinstance(b, (int, float)):
        assert a == pytest.approx(b, rel=REL, abs=1e-300), path
    else:
        assert a == b, path


def test_diagnose_equals_the_command_lines_diagnosis(cli, example, result, tmp_path):
    out = tmp_path / "diag"
    run = subprocess.run(
        [str(cli), "correct", str(example), "-o", str(out), "--diagnose", "--quiet"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert run.returncode == 0, run.stderr
    expected = json.loads((out / "diagnosis.json").read_text())
    mine = result.diagnose()
    assert mine["verdict"] in {"no_gap", "explained", "partly_explained", "unexplained"}
    _numbers_close(mine, expected)
    assert dhct.diagnose(example)["verdict"] == expected["verdict"]


def test_progress_true_reports_each_stage_on_stderr_or_tqdm(scan, capsys):
    dhct.correct(scan, progress=True)
    err = capsys.readouterr().err
    # Either tqdm's bar or one line per stage: both name the stages.
    assert "finding and fitting features" in err or "stage" in err, err


def test_displacement_fields_are_written_when_asked(example, tmp_path):
    written = dhct.correct(example, displacement=True).write(tmp_path / "o")
    for name in ("trace", "retrace"):
        assert f"displacement_{name}.npy" in written["outputs"]
        field = np.load(tmp_path / "o" / f"displacement_{name}.npy")
        assert field.shape == (2, 256, 256)
        # Drift moves the tip by up to nanometres over the frame, never by a micrometre.
        assert 1e-12 < np.abs(field).max() < 1e-6


def test_every_channel_is_written_when_asked(tmp_path):
    path = Path(__file__).resolve().parents[3] / "tests/data/real/hbn_defect_nanonis_2nm.sxm"
    result = dhct.correct(path, lattice="hexagonal", nn="2.504A", polarity="dark", channels="all")
    written = result.write(tmp_path / "o")
    for channel in ("Current", "LI_Demod_1_X", "Counter_1"):
        for name in ("trace", "retrace"):
            assert f"corrected_{channel}_{name}.tiff" in written["outputs"]


def test_map_points_puts_features_on_their_corrected_positions(result, tmp_path):
    f = result.features
    pitch = f["x_m"][1] / f["x_px"][1]
    for pass_ in ("trace", "retrace"):
        rows = np.flatnonzero(np.asarray(f["pass"]) == pass_)[::25]
        x, y = f["x_px"][rows], f["y_px"][rows]
        mapped = dhct.map_points(result, x, y, pass_=pass_)
        for axis in ("x", "y"):
            miss = np.abs(mapped[f"corrected_{axis}_m"] - f[f"corrected_{axis}_m"][rows]) / pitch
            assert miss.max() < 0.01, (pass_, axis, miss.max())
            assert np.all(np.isfinite(mapped[f"sigma_{axis}_m"]))
        # In metres, with the features' own times, from the written model.json: the same.
        result.write(tmp_path / pass_)
        again = dhct.map_points(
            tmp_path / pass_ / "model.json",
            f["x_m"][rows],
            f["y_m"][rows],
            t=f["time_s"][rows],
            pass_=pass_,
            unit="m",
        )
        np.testing.assert_allclose(again["corrected_x_m"], mapped["corrected_x_m"], rtol=0, atol=1e-3 * pitch)
    with pytest.raises(dhct.OptionError, match="outside"):
        dhct.map_points(result, [1e6], [3.0])
    with pytest.raises(dhct.OptionError, match="one length"):
        dhct.map_points(result, [1.0, 2.0], [3.0])


def test_extent_full_writes_every_corrected_pixel(scan, tmp_path):
    dhct.correct(scan, extent="full").write(tmp_path / "full")
    header = (tmp_path / "full" / "corrected_trace.gsf").read_bytes()[:400].decode("latin1")
    assert "XOffset = " in header
    with pytest.raises(dhct.OptionError, match="frame"):
        dhct.correct(scan, extent="wide")
