"""dhct.simulate: presets, seeds, config files and dicts, and simulate -> correct."""

import sys

import numpy as np
import pytest

import dhct

PRESET = "ci-small"  # 256² graphite with drift, creep, hysteresis and noise


def test_presets_listed():
    presets = dhct.presets()
    assert PRESET in presets
    assert all(isinstance(v, str) and v for v in presets.values())


def test_simulate_is_deterministic_per_seed():
    a = dhct.simulate(PRESET, seed=1)
    b = dhct.simulate(PRESET, seed=1)
    c = dhct.simulate(PRESET, seed=2)
    assert a.scan.trace.dtype == np.float64 and a.scan.trace.shape == a.scan.shape == (256, 256)
    assert a.scan.retrace is not None
    np.testing.assert_array_equal(a.scan.trace, b.scan.trace)
    assert not np.array_equal(a.scan.trace, c.scan.trace)
    assert "seed = 1" in a.config
    assert isinstance(a.truth, dict) and a.truth


def test_simulate_from_a_config_file_equals_the_preset(tmp_path):
    preset = dhct.simulate(PRESET, seed=3)
    path = tmp_path / "sim.toml"
    path.write_text(preset.config)
    from_file = dhct.simulate(path)
    np.testing.assert_array_equal(from_file.scan.trace, preset.scan.trace)


@pytest.mark.skipif(sys.version_info < (3, 11), reason="tomllib (to turn the TOML into a dict) needs Python 3.11")
def test_simulate_from_a_dict_equals_the_preset():
    import tomllib

    preset = dhct.simulate(PRESET, seed=4)
    config = tomllib.loads(preset.config)
    from_dict = dhct.simulate(config)
    np.testing.assert_array_equal(from_dict.scan.retrace, preset.scan.retrace)


def test_simulate_errors(tmp_path):
    with pytest.raises(dhct.SimulationError, match="neither a preset"):
        dhct.simulate("no-such-preset")
    with pytest.raises(dhct.SimulationError):
        dhct.simulate({"no_such_key": 1})
    bad = tmp_path / "bad.toml"
    bad.write_text("this is = = not toml")
    with pytest.raises(dhct.SimulationError):
        dhct.simulate(bad)


def test_simulated_scan_corrects():
    sim = dhct.simulate(PRESET, seed=5)
    result = dhct.correct(sim.scan)
    assert result.corrected_trace.shape == sim.scan.shape
    assert sum(p["indexed"] for p in result.model["passes"]) > 100


def test_lattice_catalogue_listed():
    lattices = dhct.lattices()
    assert len(lattices) >= 10
    for name in ("graphite", "honeycomb", "rectangular", "centred-rectangular", "oblique", "kagome"):
        assert name in lattices
    assert lattices["graphite"]["known_constant"] is True
    assert lattices["kagome"]["known_constant"] is False
    assert "graphene" in lattices["honeycomb"]["aliases"]
