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


# --- physical ranges and robot profiles ---------------------------------------------------


def _numeric_fields(cls=Config, prefix=""):
    """(dotted path, field) of every int or float field of the configuration."""
    import dataclasses
    import typing

    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        path = f"{prefix}{f.name}"
        hint = hints[f.name]
        if dataclasses.is_dataclass(hint):
            yield from _numeric_fields(hint, path + ".")
        elif hint in (int, float):
            yield path, f


def _nested(path: str, value) -> dict:
    out: dict = value
    for part in reversed(path.split(".")):
        out = {part: out}
    return out


def test_every_number_of_the_config_has_a_physical_range():
    fields = list(_numeric_fields())
    assert len(fields) > 80
    missing = [p for p, f in fields if "range" not in f.metadata]
    assert not missing, missing


# the lidar's mounting is the only place where a negative number makes sense
MAY_BE_NEGATIVE = {"slam.mount.x_m", "slam.mount.y_m", "slam.mount.yaw_rad"}


@pytest.mark.parametrize("path", [p for p, _ in _numeric_fields() if p not in MAY_BE_NEGATIVE])
def test_minus_one_is_refused_naming_the_field(path):
    with pytest.raises(ConfigError, match=path.replace(".", r"\.")):
        with_overrides(Config(), _nested(path, -1))


@pytest.mark.parametrize("bad", [float("nan"), float("inf")])
def test_non_finite_numbers_are_refused(bad):
    for path, _ in _numeric_fields():
        with pytest.raises(ConfigError):
            with_overrides(Config(), _nested(path, bad))


def test_a_profile_fills_the_robot_and_explicit_values_win(tmp_path):
    p = tmp_path / "c.toml"
    p.write_text('profile = "turtlebot3"\n[sim.lidar]\nrate_hz = 6.0\n')
    cfg = load_config(p)
    assert cfg.profile == "turtlebot3"
    assert cfg.sim.lidar.range_max_m == 3.5 and cfg.sim.lidar.beams == 360
    assert cfg.sim.lidar.rate_hz == 6.0  # the file's own value
    assert cfg.sim.robot.max_linear_mps == 0.22
    assert cfg.nav.robot_radius_m == cfg.sim.robot.radius_m == 0.105
    # the run folder's config.toml holds every value: loading it gives the same config
    save_config(cfg, tmp_path / "saved.toml")
    assert config_to_dict(load_config(tmp_path / "saved.toml")) == config_to_dict(cfg)


def test_switching_profiles_replaces_the_old_profiles_values():
    from polyswarm.config import with_profile

    tb4 = with_profile(with_profile(Config(), "turtlebot3"), "turtlebot4")
    assert tb4.sim.lidar.range_max_m == 12.0 and tb4.sim.lidar.out_of_range == "inf"
    back = with_profile(tb4, "thesis")
    assert config_to_dict(back) == config_to_dict(Config())


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ('profile = "turtlebot"', "did you mean 'turtlebot4'"),
        ("profile = 3", "profile: expected a string"),
        ('profile = "turtlebot3"\n[sim.lidar]\nrange_max_m = 0.1', "range_max_m"),
        ('profile = "turtlebot3"\n[sim.lidar]\nrate_hz = -5.0', r"sim\.lidar\.rate_hz"),
        ('profile = "turtlebot4"\n[sim.lidar]\nfov_rad = 7.0', r"sim\.lidar\.fov_rad"),
        ('profile = "turtlebot4"\n[sim.lidar]\nbeams = "many"', r"sim\.lidar\.beams"),
        ('profile = "turtlebot3"\n[sim.lidar]\nout_of_range = "none"', "out_of_range"),
    ],
)
def test_bad_profiles_and_profile_fields_are_config_errors(tmp_path, text, match):
    p = tmp_path / "c.toml"
    p.write_text(text + "\n")
    with pytest.raises(ConfigError, match=match):
        load_config(p)


def test_every_profile_loads_and_is_physically_sensible():
    from polyswarm.config import with_profile
    from polyswarm.profiles import profile_names

    for name in profile_names():
        cfg = with_profile(Config(), name)
        lid = cfg.sim.lidar
        assert 0 < lid.range_min_m < lid.range_max_m and lid.beams >= 180, name
        assert cfg.nav.robot_radius_m == cfg.sim.robot.radius_m, name
