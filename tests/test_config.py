import pytest

from polyswarm.config import Config, config_to_dict, load_config, save_config, with_overrides
from polyswarm.errors import ConfigError


def test_defaults_are_the_thesis_sensor():
    cfg = Config()
    assert cfg.sim.lidar.beams == 720
    assert cfg.sim.lidar.range_max_m == 30.0
    assert cfg.slam.refine.score_a == 1.0 and cfg.slam.refine.score_b == 4.0


def test_unknown_key_is_rejected_with_a_hint(tmp_path):
    p = tmp_path / "c.toml"
    p.write_text("[map]\ncell_size_m = 2.0\n[slam]\nkeyframe_distanc_m = 0.3\n")
    with pytest.raises(ConfigError, match="did you mean 'keyframe_distance_m'"):
        load_config(p)


def test_wrong_type_is_rejected(tmp_path):
    p = tmp_path / "c.toml"
    p.write_text('[map]\ncell_size_m = "big"\n')
    with pytest.raises(ConfigError, match="expected a number"):
        load_config(p)


def test_round_trip_through_toml(tmp_path):
    cfg = with_overrides(
        Config(), {"slam": {"keyframe_distance_m": 0.3}, "map": {"cell_size_m": 4}}
    )
    save_config(cfg, tmp_path / "c.toml")
    back = load_config(tmp_path / "c.toml")
    assert config_to_dict(back) == config_to_dict(cfg)
    assert back.map.cell_size_m == 4.0 and isinstance(back.map.cell_size_m, float)


@pytest.mark.parametrize(
    "override",
    [
        {"map": {"cell_size_m": 0.0005}},
        {"sim": {"lidar": {"range_min_m": 40.0}}},
        {"explore": {"strategy": "random"}},
        {"slam": {"refine": {"score_c": 0.0}}},
        {"nav": {"frontier_clearance_m": 0.5}},  # more than radius + margin (0.3 m)
        {"nav": {"tight_margin_m": 0.2}},  # more than clearance_margin_m
        {"nav": {"tight_margin_m": -0.01}},
    ],
)
def test_range_checks(override):
    with pytest.raises(ConfigError):
        with_overrides(Config(), override)


def test_missing_file_is_a_clear_error(tmp_path):
    with pytest.raises(ConfigError, match="not found"):
        load_config(tmp_path / "nope.toml")


def test_ranges_of_invalid_beams_must_be_positive():
    for name in ("frontier_range_m", "no_return_free_m"):
        with pytest.raises(ConfigError, match=name):
            with_overrides(Config(), {"slam": {name: 0.0}})
