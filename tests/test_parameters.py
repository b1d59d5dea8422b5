"""The declarations in use: scenes, the sensor file, the sweep spec, the odometry config; listings and the page.

Each moved onto ``paramspec``: the listings (``salo scenes NAME``, ``salo sensors
--keys``, ``salo sweep --help``, ``salo odometry --keys``) and ``docs/parameters.md``
are made from the declarations, and the old validators' behaviour holds (their own
tests, in test_scenes*.py, test_sensor.py, test_sweep_runner.py and test_icp.py, keep passing).
"""

from __future__ import annotations

import io
import re
from contextlib import redirect_stdout
from pathlib import Path

import pytest

import scenes
from odometry.config import OdometryConfig, variant_changes
from paramspec import Section, help_text, schema, unit_of
from scenes.params import CommonParams
from simlidar.sensor import SENSOR_FILE, LidarModel, SensorError, from_dict, load_preset, preset_names
from tools.cli import main
from tools.docs import PAGE, parameters_page
from tools.sweep.spec import SpecError, SweepSpec, load_spec, spec_from_dict

REPO = Path(__file__).resolve().parents[1]


# ---------------------------------------------------------------- scenes
def test_scene_parameters_are_declared_with_help_and_units():
    for name in scenes.SCENES:
        sec = scenes.scene_schema(name)
        assert sec.name == name and sec.help == scenes.SCENES[name].DESCRIPTION
        for key, p in sec.walk():  # a section's keys too (traffic)
            if isinstance(p, Section):
                assert p.help, (name, key)
                continue
            assert p.help and not p.help.endswith((", m", ", m/s", ", deg", "percent")), (name, key)
            assert p.unit == unit_of(p.name), (name, key)
            assert p.type in ("bool", "int", "float", "str", "list[str]") and not p.nullable, (name, key)


def test_salo_scenes_lists_the_declarations(capsys):
    assert main(["scenes", "canyon"]) == 0
    out = capsys.readouterr().out
    assert help_text(scenes.scene_schema("canyon"), header=True) in out
    assert "tunnel_cross_section" in out and "arch|box" in out and "[-8, 8]" in out


def test_scene_errors_name_the_scene_and_key():
    cases = [
        ({"streets_x": 1}, "scene city: key 'streets_x' must be an integer in [2, 12], got 1"),
        ({"streets_x": "three"}, "scene city: key 'streets_x' must be an integer in [2, 12], got 'three'"),
        ({"speed": 3}, "scene city: key 'speed' is unknown; did you mean 'speed_m_s'?"),
        ({"closed_loop": "maybe"}, "scene city: key 'closed_loop' must be true or false, got 'maybe'"),
        ({"building_height_max_m": 5.0}, "scene city: key 'building_height_max_m' is below building_height_min_m"),
    ]
    for overrides, text in cases:
        with pytest.raises(ValueError) as err:  # a ParamError is a ValueError, as before
            scenes.resolve_params("city", **overrides)
        assert str(err.value).startswith(text)
    # the old coercions: text, integral floats, 0/1 for a bool; floats stored as floats
    p = scenes.resolve_params("city", streets_x="3", route_blocks=2.0, closed_loop=0, speed_m_s=9)
    assert (p.streets_x, p.route_blocks, p.closed_loop, p.speed_m_s) == (3, 2, False, 9.0)
    assert type(p.speed_m_s) is float


# ---------------------------------------------------------------- sensors
def test_sensor_file_keys_are_the_models_and_the_file_forms():
    model = set(schema(LidarModel).names)
    assert model <= set(SENSOR_FILE.names)
    assert set(SENSOR_FILE.names) - model == {"rings", "ring_pitch_deg", "lowest_angle_deg"}
    for name in preset_names():  # every preset round-trips through the declared keys
        m = load_preset(name)
        assert from_dict(m.to_dict(), origin=name) == m


def test_salo_sensors_keys_lists_the_declarations():
    buf = io.StringIO()
    with redirect_stdout(buf):
        assert main(["sensors", "--keys"]) == 0
    out = buf.getvalue()
    assert help_text(SENSOR_FILE, header=True) in out
    assert "rotation_hz" in out and "(0, 360]" in out and "[0, 1)" in out
    buf = io.StringIO()
    with redirect_stdout(buf):
        assert main(["sensors"]) == 0
    assert "salo32" in buf.getvalue() and "--keys" in buf.getvalue()


def test_sensor_errors_keep_their_shape():
    base = load_preset("vlp16").to_dict()
    cases = [
        ({"spin": 3}, "my.yaml (sensor 'vlp16'): key 'spin' is unknown (known: name, rings, azimuth_step_deg,"),
        ({"rotation_hz": "10"}, "my.yaml (sensor 'vlp16'): key 'rotation_hz' must be a number > 0 (Hz), got '10'"),
        ({"start_azimuth_deg": None}, "my.yaml (sensor 'vlp16'): key 'start_azimuth_deg' must be a number (deg), "
                                      "got null"),
        ({"min_range_m": 200.0}, "my.yaml (sensor 'vlp16'): key 'min_range_m' must be < max_range_m"),
        ({"description": 3}, "my.yaml (sensor 'vlp16'): key 'description' must be a string, got 3"),
    ]
    for change, text in cases:
        with pytest.raises(SensorError) as err:
            from_dict({**base, **change}, origin="my.yaml")
        assert str(err.value).startswith(text)
    with pytest.raises(SensorError) as err:
        load_preset("vlp16").with_overrides(range_noise_std_m=-1.0)
    assert str(err.value) == "sensor 'vlp16': key 'range_noise_std_m' must be a number >= 0 (m), got -1.0"


# ---------------------------------------------------------------- sweep specs
def test_sweep_spec_round_trips_and_lists_its_keys(capsys):
    example = load_spec(REPO / "tools/sweep/examples/noise-study.yaml")
    assert spec_from_dict(example.to_dict()) == example
    with_configs = spec_from_dict({"configs": {"v4": {"base": "bl", "filter": {"voxel_size_m": 0.4}}},
                                   "variants": ["v4"]})
    assert spec_from_dict(with_configs.to_dict()) == with_configs
    assert schema(SweepSpec).names == tuple(SweepSpec().to_dict())  # every YAML key is declared
    with pytest.raises(SystemExit):
        main(["sweep", "--help"])
    out = capsys.readouterr().out
    assert help_text(schema(SweepSpec), header=True) in out


def test_sweep_spec_errors_come_from_the_declarations():
    cases = [
        ({"scene": ["city"]}, "s.yaml: key 'scene' is unknown; did you mean 'scenes'?"),
        ({"frames": 10.0}, "s.yaml: key 'frames' must be an integer >= 2, got 10.0"),
        ({"speed_m_s": "8"}, "s.yaml: key 'speed_m_s' must be a number > 0 (m/s) or null, got '8'"),
        ({"noise_std_m": [0.01, "a"]}, "s.yaml: key 'noise_std_m' has 'a', which is not a number >= 0 (m)"),
        ({"motion_distortion": None}, "s.yaml: key 'motion_distortion' must be true or false, got null"),
        ({"scene_params": {"city": {"speed_m_s": 100}}},
         "s.yaml: key 'scene_params.city.speed_m_s' must be a number in [0.5, 60] (m/s), got 100"),
    ]
    for change, text in cases:
        with pytest.raises(SpecError) as err:
            spec_from_dict(change, origin="s.yaml")
        assert str(err.value).startswith(text)
    # still accepted as before: one value for an axis, nulls for the optional keys
    spec = spec_from_dict({"seeds": 3, "sensors": "vlp16", "speed_m_s": None, "noise_std_m": None,
                           "scene_params": None})
    assert (spec.seeds, spec.sensors, spec.speed_m_s, spec.noise_std_m, spec.scene_params) == ((3,), ("vlp16",),
                                                                                               None, None, {})
    with pytest.raises(SpecError, match="key 'frames' must be an integer >= 2, got 1"):
        SweepSpec(frames=1)  # built directly, validated too


# ---------------------------------------------------------------- odometry configs
def test_salo_odometry_keys_lists_the_declarations_and_the_variants(capsys):
    assert main(["odometry", "--keys"]) == 0
    out = capsys.readouterr().out
    assert help_text(schema(OdometryConfig), header=True) in out
    assert "ncf.max_normal_std_deg" in out and "filtered|map" in out and "[0, 1)" in out
    assert variant_changes()["bl"] == {"ncf.enabled": False, "gcr.enabled": False} and variant_changes()["salo"] == {}
    assert "  bl        ncf.enabled: false, gcr.enabled: false\n" in out


# ---------------------------------------------------------------- the page
def test_the_parameters_page_is_what_the_declarations_make():
    assert PAGE.read_text() == parameters_page(), "docs/parameters.md is out of date: run python -m tools.docs"
    page = parameters_page()
    for name in scenes.SCENES:
        assert f"### {name}" in page
    odometry = [name for name, m in schema(OdometryConfig).walk() if not isinstance(m, Section)]
    assert "filter.voxel_size_m" in odometry and "ncf.max_normal_std_deg" in odometry
    sensor = [name for name, m in SENSOR_FILE.walk() if not isinstance(m, Section)]
    assert "weather.fog.mor_m" in sensor and "receiver.detection_range_m" in sensor
    assert "imu.gyroscope_noise_density" in sensor
    common = [name for name, m in schema(CommonParams).walk() if not isinstance(m, Section)]  # traffic.* too
    for key in (*sensor, *schema(SweepSpec).names, *common, *odometry):
        assert f"| `{key}` |" in page, key


def test_every_odometry_key_says_why_it_exists():
    """docs/keys.md lists every declared odometry key with a reason, and no key that is not declared."""
    page = (PAGE.parent / "keys.md").read_text()
    declared = [name for name, m in schema(OdometryConfig).walk() if not isinstance(m, Section)]
    listed = re.findall(r"^\| `([a-z_.]+)` \| \S", page, re.M)
    assert sorted(listed) == sorted(declared)


def test_a_removed_key_is_refused_with_its_reason():
    """Options measured and not kept are gone; a config or --set that names one is told so, with the record."""
    from odometry.config import REMOVED_KEYS, ConfigError, changes_from_assignments, config_from_dict

    for dotted in REMOVED_KEYS:
        with pytest.raises(ConfigError, match=f"{dotted}.*was removed.*Measured and not kept"):
            changes_from_assignments([f"{dotted}=1"])
        section, key = dotted.split(".")
        with pytest.raises(ConfigError, match="was removed"):
            config_from_dict({section: {key: 1}}, origin="old.yaml")
    with pytest.raises(ConfigError, match="'raw' was removed"):
        changes_from_assignments(["match.target=raw"])

