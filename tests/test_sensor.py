"""Sensor model: presets, validation errors, ring order, timing, YAML round trip."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from simlidar.sensor import (
    SensorError,
    from_dict,
    load_preset,
    load_sensor,
    load_sensor_file,
    preset_names,
)

BASE = {
    "name": "t",
    "rings": 4,
    "vertical_angles_deg": [-3.0, 1.0, -1.0, 3.0],
    "azimuth_step_deg": 0.2,
    "rotation_hz": 10.0,
    "range_noise_std_m": 0.02,
    "min_range_m": 0.5,
    "max_range_m": 100.0,
}


def test_presets_exist_and_match_published_figures():
    assert set(preset_names()) >= {"salo32", "vlp16", "hdl32e", "hdl64e", "os1-64"}
    s = load_preset("salo32")
    assert s.rings == 32 and s.azimuth_step_deg == pytest.approx(0.08)
    assert np.allclose(np.degrees(np.diff(s.elevation_rad)), 0.26)
    assert s.rays_per_sweep == 4500 * 32
    v = load_preset("vlp16")
    assert np.allclose(np.degrees(v.elevation_rad), np.arange(-15, 16, 2))
    # firing cycle 55.296 us at 10 Hz (ros-drivers rawdata.h)
    assert v.column_period_s == pytest.approx(55.296e-6, rel=1e-4)
    h = load_preset("hdl32e")
    assert np.allclose(np.degrees(h.elevation_rad), -30.67 + np.arange(32) * 4 / 3, atol=0.01)
    assert load_preset("hdl64e").rings == 64 and load_preset("os1-64").rings == 64


def test_rings_are_ordered_by_elevation_and_keep_firing_order():
    s = from_dict(BASE)
    assert np.allclose(np.degrees(s.elevation_rad), [-3, -1, 1, 3])
    # table order is firing order: -3 fires first (slot 0), 1 second, -1 third, 3 fourth
    assert list(s.ring_firing_slot) == [0, 2, 1, 3]
    assert list(s.ring_of_elevation(np.radians([-2.9, -1.2, 0.8, 2.1, 10.0]))) == [0, 1, 2, 3, 3]
    assert np.isnan(s.ring_pitch_below_rad[0]) and np.isnan(s.ring_pitch_above_rad[-1])
    assert np.allclose(np.degrees(s.ring_pitch_above_rad[:-1]), 2.0)


def test_firing_times_follow_columns_then_laser_slots():
    s = from_dict({**BASE, "laser_interval_s": 1e-6})
    t = s.firing_time_s(np.array([0, 1, 2, 3]), np.array([0, 0, 0, 5]))
    assert np.allclose(t, [0.0, 2e-6, 1e-6, 5 * s.column_period_s + 3e-6])
    assert s.column_period_s * s.columns_per_sweep <= s.sweep_period_s + 1e-12


def test_uniform_pitch_form():
    d = {k: v for k, v in BASE.items() if k != "vertical_angles_deg"}
    s = from_dict({**d, "ring_pitch_deg": 0.5, "lowest_angle_deg": -2.0})
    assert np.allclose(np.degrees(s.elevation_rad), [-2.0, -1.5, -1.0, -0.5])


def test_yaml_round_trip(tmp_path):
    s = load_preset("os1-64").with_overrides(range_noise_std_m=0.05, ring_bias_std_m=0.01)
    s.save(tmp_path / "s.yaml")
    r = load_sensor_file(tmp_path / "s.yaml")
    assert r == s
    assert load_sensor(tmp_path / "s.yaml") == s


@pytest.mark.parametrize(
    "change, key, words",
    [
        ({"rings": None}, "rings", "missing"),
        ({"rings": 5}, "rings", "4 angles"),
        ({"range_noise_std_m": -0.1}, "range_noise_std_m", "must be a number >= 0 (m), got -0.1"),
        ({"min_range_m": 100.0}, "min_range_m", "< max_range_m"),
        ({"azimuth_step_deg": 0.0}, "azimuth_step_deg", "(0, 360]"),
        ({"azimuth_step_deg": -1.0}, "azimuth_step_deg", "(0, 360]"),
        ({"rotation_hz": "fast"}, "rotation_hz", "number"),
        ({"spin": 3}, "spin", "is unknown"),
        ({"vertical_angles_deg": [1, 1, 2, 3]}, "vertical_angles_deg", "repeated"),
        ({"dropout_probability": 1.5}, "dropout_probability", "[0, 1)"),
    ],
)
def test_validation_names_key_and_problem(change, key, words):
    d = dict(BASE)
    for k, v in change.items():
        if v is None:
            d.pop(k)
        else:
            d[k] = v
    with pytest.raises(SensorError) as err:
        from_dict(d, origin="my.yaml")
    msg = str(err.value)
    assert "my.yaml" in msg and f"'{key}'" in msg and words in msg


def test_unknown_preset_lists_known_ones():
    with pytest.raises(SensorError) as err:
        load_sensor("velodyne-999")
    assert "velodyne-999" in str(err.value) and "salo32" in str(err.value) and "vlp16" in str(err.value)


def test_bad_yaml_file_names_the_file(tmp_path):
    p = tmp_path / "bad.yaml"
    p.write_text("name: [unclosed")
    with pytest.raises(SensorError, match="bad.yaml"):
        load_sensor_file(p)
    p.write_text(yaml.safe_dump({**BASE, "rings": 3}))
    with pytest.raises(SensorError, match="bad.yaml.*'rings' is 3 but vertical_angles_deg lists 4"):
        load_sensor_file(p)
