"""dhct.correct_series on a simulated sequence: the drift at each frame's start against the
simulator's truth, and the refusals a series needs."""

import json

import pytest

import dhct


def _small_sequence(tmp_path, frames=3):
    """A short, small sequence (the graphite-sequence preset cut down) written to disk."""
    config = tmp_path / "sequence.toml"
    config.write_text(
        """
name = "small-sequence"
seed = 5
[scan]
columns = 128
rows = 128
width_m = 3e-9
height_m = 3e-9
fast_speed_m_per_s = 30e-9
trace_fast = "right"
slow = "down"
[surface]
lattice = { kind = "graphite" }
feature = { height_m = 40e-12, sigma_m = [0.6e-10, 0.6e-10] }
[noise]
white_sigma_m = 2e-12
[[effects]]
kind = "fast-hysteresis"
law = { kind = "power", k = 0.95, n = -0.03 }
[sequence]
frames = %d
pause_s = 2.0
drift = { velocity_m_per_s = [4e-12, -3e-12] }
"""
        % frames
    )
    out = tmp_path / "frames"
    written = dhct.simulate_sequence(str(config), out)
    assert any(p.endswith("sequence_truth.json") for p in written)
    return out


def test_the_drift_at_each_frame_start_matches_the_truth(tmp_path):
    frames = _small_sequence(tmp_path)
    summary = dhct.correct_series(str(frames / "*.sm4"), tmp_path / "out")
    truth = json.loads((frames / "sequence_truth.json").read_text())
    assert len(summary["frames"]) == 3
    pitch = 3e-9 / 128
    # The session frame is the first frame as its files place it, on average: the drift is
    # compared from the first frame's start on.
    starts = summary["fit"]["frame_starts"]
    first = starts[0]["displacement_m"]
    for fitted, true in zip(starts, truth["frames"]):
        d = [fitted["displacement_m"][i] - first[i] for i in range(2)]
        t = true["displacement_at_start_m"]
        assert abs(d[0] - t[0]) < 0.1 * pitch and abs(d[1] - t[1]) < 0.1 * pitch, (d, t)
    assert truth["frames"][1]["displacement_at_start_m"][0] > pitch, "the test needs a drift" 
    assert (tmp_path / "out" / "registered" / "stack.tif").is_file()


def test_one_frame_is_not_a_series(tmp_path):
    frames = _small_sequence(tmp_path, frames=2)
    with pytest.raises(dhct.AnalysisError, match="at least two frames"):
        dhct.correct_series(frames / "frame_00.sm4", tmp_path / "out")
    with pytest.raises(dhct.OptionError):
        dhct.correct_series(frames, tmp_path / "out", retrace="x")


def test_frames_without_a_resolved_lattice_are_registered_by_their_images(tmp_path):
    config = tmp_path / "molecules.toml"
    config.write_text(
        """
name = "molecules"
seed = 7
[scan]
columns = 128
rows = 128
width_m = 12e-9
height_m = 12e-9
fast_speed_m_per_s = 150e-9
trace_fast = "right"
slow = "down"
[surface]
lattice = { kind = "hexagonal", a_m = 1.4e-9 }
feature = { height_m = 40e-12, sigma_m = [2.5e-10, 2.5e-10] }
defects = { vacancy_fraction = 0.6 }
[noise]
white_sigma_m = 2e-12
[sequence]
frames = 3
pause_s = 2.0
drift = { velocity_m_per_s = [4e-12, -3e-12] }
"""
    )
    frames = tmp_path / "frames"
    dhct.simulate_sequence(str(config), frames)
    summary = dhct.correct_series(str(frames / "*.sm4"), tmp_path / "out", register="image")
    assert summary["registration"] == "image"
    assert any("scale" in u for u in summary["undetermined"])
    truth = json.loads((frames / "sequence_truth.json").read_text())
    pitch = 12e-9 / 128
    starts = [s["displacement_m"] for s in summary["drift"]["frame_starts"]]
    true = [f["displacement_at_start_m"] for f in truth["frames"]]
    # Up to the session frame's place (a constant comparisons cannot fix: the mean
    # difference over the frames is taken out).
    for i in range(2):
        errors = [starts[k][i] - true[k][i] for k in range(3)]
        centre = sum(errors) / 3
        assert all(abs(e - centre) < 0.15 * pitch for e in errors), (i, errors)
    assert abs(true[2][0] - true[0][0]) > 1.5 * pitch, "the test needs a drift"
    # A perfect lattice shares its pattern at every period: refused, not guessed.
    (tmp_path / "graphite").mkdir()
    graphite = _small_sequence(tmp_path / "graphite", frames=2)
    with pytest.raises(dhct.AnalysisError, match="no common structure"):
        dhct.correct_series(graphite, tmp_path / "out2", register="image")
    with pytest.raises(dhct.OptionError):
        dhct.correct_series(graphite, tmp_path / "out3", register="features")
