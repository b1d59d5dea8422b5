"""Sensor effects that break odometry, each against its analytic expectation (all off by default).

- beam divergence: mixed pixels at a depth edge, the echo the return mode picks;
- range noise growing with incidence: sigma0 / cos(incidence), clipped;
- intensity from a per-object reflectance and the incidence angle.
"""

from __future__ import annotations

import numpy as np
import pytest

from simlidar.sensor import LidarModel, SensorError, from_dict, load_sensor, load_sensor_file
from simlidar.sweep import SweepSimulator
from simlidar.trajectory import SampledTrajectory
from simlidar.world import LABEL_REFLECTANCE, World, WorldError
from tests.helpers import ground_plane


def _still(position=(0.0, 0.0, 0.0)) -> SampledTrajectory:
    T = np.eye(4)
    T[:3, 3] = position
    return SampledTrajectory(np.array([0.0]), T[None])


def _quads(quads: list[tuple[np.ndarray, int]], labels: list[str]) -> World:
    """Quads (4 corners, counter-clockwise seen from the side they face) with their object ids."""
    verts, faces, ids = [], [], []
    for k, (corners, obj) in enumerate(quads):
        verts.append(corners)
        faces += [[4 * k, 4 * k + 1, 4 * k + 2], [4 * k, 4 * k + 2, 4 * k + 3]]
        ids += [obj, obj]
    return World(np.vstack(verts), np.array(faces), np.array(ids), labels, "plates")


def _plate_x(x: float, y0: float, y1: float, z0: float = -5.0, z1: float = 5.0) -> np.ndarray:
    """A rectangle in the plane x = const facing -x (towards a sensor at the origin)."""
    return np.array([[x, y0, z0], [x, y0, z1], [x, y1, z1], [x, y1, z0]])


def _edge_sensor(**effects) -> LidarModel:
    """One ring at 0 deg, 1 deg columns, column 0 along +x; no noise."""
    return LidarModel(name="edge", vertical_angles_deg=(0.0,), azimuth_step_deg=1.0, rotation_hz=10.0,
                      range_noise_std_m=0.0, min_range_m=0.5, max_range_m=100.0, start_azimuth_deg=0.0, **effects)


def _expected_echoes(sensor: LidarModel, surfaces, reflectance):
    """Per sub-ray of column 0's beam (axis +x; across = axis x z = -y, up = z): which surface it hits,
    its range and power, from the geometry alone. surfaces: (x, y0, y1, object) plates facing -x."""
    off = sensor.beam_pattern_rad()
    r = np.hypot(off[:, 0], off[:, 1])
    d = np.column_stack([np.cos(r), -np.sin(r) * off[:, 0] / r, np.sin(r) * off[:, 1] / r])
    best = np.full(len(d), np.inf)
    power = np.zeros(len(d))
    which = np.full(len(d), -1)
    for x, y0, y1, obj in surfaces:
        t = x / d[:, 0]
        y = t * d[:, 1]
        hit = (y >= y0) & (y <= y1) & (t < best)
        best[hit], which[hit] = t[hit], obj
        power[hit] = reflectance[obj] * d[hit, 0] / t[hit] ** 2  # cos incidence = d_x
    return best, power, which


def _column0_range(world: World, sensor: LidarModel) -> tuple[float, float]:
    scan = SweepSimulator(world, sensor, seed=0, motion_distortion=False).sweep(_still(), 0.0)
    row = np.flatnonzero(scan.azimuth_index == 0)
    assert len(row) == 1
    return float(scan.range_m[row[0]]), float(scan.true_range_m[row[0]])


@pytest.mark.parametrize("mode", ["first", "last", "strongest"])
@pytest.mark.parametrize("plate_reflectance", [0.9, 0.05])
def test_a_beam_straddling_a_plate_edge_returns_the_echo_its_mode_picks(mode, plate_reflectance):
    # A plate at 10 m covering y >= 0.05 in front of a wall at 20 m: the beam's axis (y = 0) passes the
    # plate's edge and hits the wall; about a third of its 2 deg cone falls on the plate.
    surfaces = [(10.0, 0.05, 5.0, 1), (20.0, -50.0, 50.0, 0)]
    world = _quads([(_plate_x(20.0, -50.0, 50.0, -50.0, 50.0), 0), (_plate_x(10.0, 0.05, 5.0), 1)],
                   ["wall", "plate"]).with_reflectance({"plate": plate_reflectance, "wall": 0.5})
    sensor = _edge_sensor(beam_divergence_deg=2.0, beam_subrays=64, return_mode=mode, echo_separation_m=0.5)
    dist, power, which = _expected_echoes(sensor, surfaces, world.object_reflectance)
    on_plate = which == 1
    assert 0.2 < on_plate.mean() < 0.45 and np.all(which >= 0)
    near = np.average(dist[on_plate], weights=power[on_plate])
    far = np.average(dist[~on_plate], weights=power[~on_plate])
    expected = {"first": near, "last": far,
                "strongest": near if power[on_plate].sum() > power[~on_plate].sum() else far}[mode]
    measured, true = _column0_range(world, sensor)
    assert true == pytest.approx(20.0, abs=1e-9)  # the truth is the axis ray's: the wall
    assert measured == pytest.approx(expected, abs=1e-9)
    if mode == "strongest":  # a bright plate outshines the wall at twice its range; a dark one does not
        assert (measured < 15) == (plate_reflectance == 0.9)


def test_a_plate_just_in_front_of_a_wall_mixes_into_a_range_between_them():
    # 0.3 m apart, within one echo (0.5 m): every mode reports the power-weighted mean, the mixing
    # fraction of the plate's sub-rays pulling it from the wall towards the plate.
    surfaces = [(10.0, 0.05, 5.0, 1), (10.3, -50.0, 50.0, 0)]
    world = _quads([(_plate_x(10.3, -50.0, 50.0, -50.0, 50.0), 0), (_plate_x(10.0, 0.05, 5.0), 1)],
                   ["wall", "plate"])
    for mode in ("first", "last", "strongest"):
        sensor = _edge_sensor(beam_divergence_deg=2.0, beam_subrays=64, return_mode=mode, echo_separation_m=0.5)
        dist, power, which = _expected_echoes(sensor, surfaces, world.object_reflectance)
        f = power[which == 1].sum() / power.sum()  # the plate's share of the power
        measured, true = _column0_range(world, sensor)
        assert true == pytest.approx(10.3, abs=1e-9)
        assert measured == pytest.approx(np.average(dist, weights=power), abs=1e-9)
        assert 10.0 < measured < 10.3 and 0.2 < f < 0.5
        assert measured == pytest.approx(10.3 - 0.3 * f, abs=2e-3)  # ranges differ by 1e-3 over the cone


def test_without_divergence_the_beam_reports_its_axis_hit():
    world = _quads([(_plate_x(20.0, -50.0, 50.0, -50.0, 50.0), 0), (_plate_x(10.0, 0.05, 5.0), 1)], ["wall", "plate"])
    measured, true = _column0_range(world, _edge_sensor())
    assert measured == true == pytest.approx(20.0, abs=1e-9)


@pytest.mark.parametrize("factor", [1.0, 6.0])
def test_range_noise_grows_as_one_over_cos_incidence_up_to_its_clip(factor):
    # Flat ground 2 m below a vlp16: ring e meets it at cos(incidence) = sin(|e|), the same for every
    # column, so each ring's residuals have std sigma0 * min(1 / sin|e|, factor).
    sigma0 = 0.01
    sensor = load_sensor("vlp16").with_overrides(range_noise_std_m=sigma0, incidence_noise_max_factor=factor)
    sim = SweepSimulator(ground_plane(z=-2.0, half=1000.0), sensor, seed=3, motion_distortion=False)
    scans = [sim.sweep(_still(), 0.1 * k, frame_index=k) for k in range(2)]
    ring = np.concatenate([s.ring for s in scans])
    res = np.concatenate([s.range_m - s.true_range_m for s in scans])
    checked = 0
    for r in np.unique(ring):
        e = sensor.elevation_rad[r]
        rows = ring == r
        if e > -np.radians(2.5) or rows.sum() < 3000:
            continue
        expected = sigma0 * min(1.0 / np.sin(-e), factor)
        assert res[rows].std() == pytest.approx(expected, rel=0.05), np.degrees(e)
        assert abs(res[rows].mean()) < 4 * expected / np.sqrt(rows.sum())
        checked += 1
    assert checked >= 6


def test_intensity_follows_the_object_reflectance_and_the_incidence():
    # Ground (object 0) and a wall (object 1) with set reflectances, k = 2: intensity =
    # reflectance * |cos a|^2 * min(1, (10 m / r)^2), cos a from the truth's beam and normal.
    wall = np.array([[15.0, -40.0, -3.0], [15.0, -40.0, 10.0], [15.0, 40.0, 10.0], [15.0, 40.0, -3.0]])
    ground = np.array([[-60.0, -60.0, -1.8], [60.0, -60.0, -1.8], [60.0, 60.0, -1.8], [-60.0, 60.0, -1.8]])
    labelled = _quads([(ground, 0), (wall[[0, 3, 2, 1]], 1)], ["ground", "wall"])
    world = labelled.with_reflectance({"0": 0.2, "wall": 0.7})
    sensor = load_sensor("vlp16").with_overrides(intensity_incidence_exponent=2.0, range_noise_std_m=0.02)
    scan = SweepSimulator(world, sensor, seed=1, motion_distortion=False).sweep(_still(), 0.0)
    assert set(np.unique(scan.object_id)) == {0, 1}
    beam = scan.xyz / np.linalg.norm(scan.xyz, axis=1, keepdims=True)
    cos = np.abs(np.einsum("ij,ij->i", beam, scan.normal))
    expected = np.array([0.2, 0.7])[scan.object_id] * cos**2 * np.minimum(1.0, (10.0 / scan.range_m) ** 2)
    assert np.abs(scan.intensity - expected).max() < 1e-6
    # the default (k = 1, reflectance from the labels) is the formula docs/simulation.md gives
    plain = SweepSimulator(labelled, load_sensor("vlp16"), seed=1, motion_distortion=False).sweep(_still(), 0.0)
    beam = plain.xyz / np.linalg.norm(plain.xyz, axis=1, keepdims=True)
    cos = np.abs(np.einsum("ij,ij->i", beam, plain.normal))
    expected = np.array([LABEL_REFLECTANCE["ground"], LABEL_REFLECTANCE["wall"]])[plain.object_id] * cos * \
        np.minimum(1.0, (10.0 / plain.range_m) ** 2)
    assert np.abs(plain.intensity - expected).max() < 1e-6


def test_reflectance_errors_name_the_world_and_the_key():
    world = ground_plane()
    with pytest.raises(WorldError, match="ground plane: reflectance for 'asphalt', which is neither"):
        world.with_reflectance({"asphalt": 0.1})
    with pytest.raises(WorldError, match="reflectance for object 3, but the world has 1 objects"):
        world.with_reflectance({3: 0.1})
    with pytest.raises(WorldError, match="reflectance must lie in"):
        world.with_reflectance({"ground": 1.5})


def test_effect_keys_in_a_sensor_file_round_trip_and_bad_values_are_one_line_errors(tmp_path):
    base = load_sensor("vlp16")
    assert "beam_divergence_deg" not in base.to_dict()  # off: the files of existing sensors are unchanged
    on = base.with_overrides(beam_divergence_deg=0.3, beam_subrays=9, return_mode="last", echo_separation_m=0.4,
                             incidence_noise_max_factor=5.0, intensity_incidence_exponent=1.5)
    on.save(tmp_path / "s.yaml")
    assert load_sensor_file(tmp_path / "s.yaml") == on
    data = on.to_dict()
    for key, value, problem in (("return_mode", "middle", "return_mode"), ("beam_subrays", 1, "beam_subrays"),
                                ("incidence_noise_max_factor", 0.5, "incidence_noise_max_factor"),
                                ("beam_divergence_deg", -1, "beam_divergence_deg")):
        with pytest.raises(SensorError, match=rf"bad.yaml.*{problem}") as info:
            from_dict({**data, key: value}, origin=str(tmp_path / "bad.yaml"))
        assert "\n" not in str(info.value)


def test_the_effect_sensor_files_for_the_ncf_study_load_with_one_effect_each():
    from pathlib import Path

    folder = Path(__file__).resolve().parents[1] / "tools/experiments/effects"
    base = load_sensor("salo32").to_dict()
    files = sorted(folder.glob("*.yaml"))
    assert [f.stem for f in files] == ["salo32-divergence", "salo32-incidence", "salo32-intensity"]
    for f in files:
        on = load_sensor_file(f).to_dict()
        changed = {k for k in on if on[k] != base.get(k)} - {"name", "description"}
        assert changed and changed <= {"beam_divergence_deg", "beam_subrays", "return_mode", "echo_separation_m",
                                       "incidence_noise_max_factor", "intensity_incidence_exponent"}, (f, changed)
