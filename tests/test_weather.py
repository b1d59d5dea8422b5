"""The receiver's power model and the weather (``simlidar.weather``), each against its analytic expectation.

- fog's two-way attenuation with the detection threshold: per beam on tiles of known reflectance and range,
  and the return rate against range, exp(-2 alpha R) included;
- fog's backscatter: its peak and half-power span against the integral of the lidar equation computed by
  quadrature, the detection rate of beams into the sky against the Gamma fluctuation's survival function,
  the ranges against the uniform span, and the rate at which it replaces a wall's return;
- rain and snow: returns per beam against 1 - exp(-mu) with mu the integrated rate of detectable particles
  of the drop-size distribution, and (return mode "first") their ranges against the first-arrival law;
- the truth: weather flags, the surface behind, the truth format's weather block; seeds and order;
  the keys (off by default, one-line errors, round trip), and what a method is handed.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate, optimize, stats

from simlidar.sensor import LidarModel, SensorError, from_dict, load_sensor, load_sensor_file
from simlidar.sweep import SweepSimulator
from simlidar.trajectory import SampledTrajectory
from simlidar.weather import (
    FOG,
    RAIN,
    SNOW,
    SURFACE,
    FogParams,
    RainParams,
    ReceiverParams,
    SnowParams,
    Weather,
    WeatherModel,
)
from simlidar.world import World

C = 299_792_458.0


def _still() -> SampledTrajectory:
    return SampledTrajectory(np.array([0.0]), np.eye(4)[None])


def _ring(**keys) -> LidarModel:
    """One level ring, 0.1 deg columns (3600 beams), column 0 along +x, no noise."""
    return LidarModel(name="ring", vertical_angles_deg=(0.0,), azimuth_step_deg=0.1, rotation_hz=10.0,
                      range_noise_std_m=0.0, min_range_m=0.5, max_range_m=250.0, start_azimuth_deg=0.0, **keys)


def _sky() -> World:
    """Nothing the level ring can see: one small triangle far below the sensor (Embree needs a mesh)."""
    return World(np.array([[0.0, 0.0, -500.0], [1.0, 0.0, -500.0], [0.0, 1.0, -500.0]]), np.array([[0, 1, 2]]),
                 np.zeros(1), ["ground"], "sky")


def _tiles(ranges: np.ndarray, reflectance: np.ndarray, sensor: LidarModel) -> World:
    """A small square tile facing the sensor across each column's beam at ``ranges[c]`` (normal incidence),
    its own object of reflectance ``reflectance[c]``."""
    az = sensor.column_azimuth_rad(np.arange(len(ranges)))
    half = np.radians(0.04) * ranges  # narrower than a column: each beam meets its own tile only
    d = np.column_stack([np.cos(az), np.sin(az), np.zeros_like(az)])
    side = np.column_stack([-np.sin(az), np.cos(az), np.zeros_like(az)])
    up = np.array([0.0, 0.0, 1.0])
    centre = d * ranges[:, None]
    corners = np.stack([centre - side * half[:, None] - up * half[:, None],
                        centre + side * half[:, None] - up * half[:, None],
                        centre + side * half[:, None] + up * half[:, None],
                        centre - side * half[:, None] + up * half[:, None]], axis=1)
    base = 4 * np.arange(len(ranges))[:, None]
    faces = np.concatenate([base + [0, 2, 1], base + [0, 3, 2]])
    ids = np.concatenate([np.arange(len(ranges))] * 2)
    return World(corners.reshape(-1, 3), faces, ids, ["wall"] * len(ranges), "tiles", reflectance=reflectance)


def _foggy(mor: float, **fog) -> dict:
    return {"receiver": ReceiverParams(enabled=True),
            "weather": Weather(fog=FogParams(enabled=True, mor_m=mor, **fog))}


# ---------------------------------------------------------------- fog: attenuation and the threshold
def test_fog_loses_far_and_dark_returns_as_exp_minus_2_alpha_r_under_the_threshold():
    # 3600 tiles at normal incidence, ranges 12..200 m, reflectance uniform in (0, 1); no backscatter
    # (beta 0): a beam returns iff rho exp(-2 alpha R) / R^2 >= 0.1 / 100^2.
    rng = np.random.default_rng(5)
    n = 3600
    ranges = rng.uniform(12.0, 200.0, n)
    rho = rng.uniform(0.0, 1.0, n)
    mor = 150.0
    sensor = _ring(**_foggy(mor, beta_times_mor=0.0))
    world = _tiles(ranges, rho, sensor)
    scan = SweepSimulator(world, sensor, seed=0, motion_distortion=False).sweep(_still(), 0.0)
    alpha = math.log(20.0) / mor
    p_min = 0.1 / 100.0**2
    expected = rho * np.exp(-2 * alpha * ranges) / ranges**2 >= p_min
    got = np.zeros(n, bool)
    got[scan.azimuth_index] = True
    assert np.array_equal(got, expected)
    assert np.all(scan.weather == SURFACE)
    np.testing.assert_allclose(scan.range_m, ranges[scan.azimuth_index], atol=1e-9)
    # intensity: the clear-air model times the two-way transmission
    r = scan.range_m
    clear = rho[scan.azimuth_index] * np.minimum(1.0, (10.0 / r) ** 2)
    np.testing.assert_allclose(scan.intensity, clear * np.exp(-2 * alpha * r), rtol=1e-5, atol=1e-7)
    # the return rate against range, in 20 m bins, against E_rho[1(rho >= p_min R^2 exp(2 alpha R))]
    edges = np.arange(20.0, 201.0, 20.0)
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        sel = (ranges >= lo) & (ranges < hi)
        rr = np.linspace(lo, hi, 201)
        rate = np.mean(1.0 - np.minimum(1.0, p_min * rr**2 * np.exp(2 * alpha * rr)))
        k = sel.sum()
        assert abs(got[sel].mean() - rate) < 4 * math.sqrt(max(rate * (1 - rate), 1e-3) / k) + 1e-9, (lo, rate)
    # clear air with the same receiver loses only by the threshold: the fog made the difference
    clear_sensor = _ring(receiver=ReceiverParams(enabled=True))
    clear_scan = SweepSimulator(world, clear_sensor, seed=0, motion_distortion=False).sweep(_still(), 0.0)
    assert len(clear_scan) == int((rho / ranges**2 >= p_min).sum()) > len(scan)


def test_an_ideal_receiver_and_a_clear_receiver_return_the_same_near_bright_surfaces():
    rng = np.random.default_rng(1)
    ranges, rho = rng.uniform(12.0, 30.0, 3600), rng.uniform(0.3, 1.0, 3600)
    ideal = _ring()
    world = _tiles(ranges, rho, ideal)
    a = SweepSimulator(world, ideal, seed=2, motion_distortion=False).sweep(_still(), 0.0)
    b = SweepSimulator(world, _ring(receiver=ReceiverParams(enabled=True)), seed=2,
                       motion_distortion=False).sweep(_still(), 0.0)
    assert a.weather is None and b.weather is None  # the receiver alone is no weather
    np.testing.assert_array_equal(a.range_m, b.range_m)
    np.testing.assert_allclose(a.intensity, b.intensity)


# ---------------------------------------------------------------- fog: backscatter
def _soft_by_quadrature(rec: ReceiverParams, alpha: float, min_range: float, r0: float = math.inf):
    """(peak S, span lo, span hi) of the fog's echo, in reported range, from the paper's integral by quadrature."""
    L = C * rec.pulse_width_s

    def xi(x):
        return float(rec.overlap(x))

    def S(rep):
        pos = rep + L / 2
        lo, hi = max(pos - L, 0.0), min(pos, r0)
        if hi <= lo:
            return 0.0
        f = lambda x: math.sin(math.pi * (pos - x) / L) ** 2 * xi(x) * math.exp(-2 * alpha * x) / x**2  # noqa: E731
        pts = [p for p in (rec.overlap_start_m, rec.overlap_full_m) if lo < p < hi]
        return integrate.quad(f, lo, hi, points=pts or None, limit=200, epsabs=1e-12)[0]

    top = min(r0, 60.0)
    grid = np.arange(min_range, top, 0.05)
    vals = np.array([S(r) for r in grid])
    j = int(np.argmax(vals))
    res = optimize.minimize_scalar(lambda r: -S(r), bounds=(grid[max(j - 1, 0)], grid[min(j + 1, len(grid) - 1)]),
                                   method="bounded", options={"xatol": 1e-6})
    peak = -res.fun
    arg = res.x
    lo = min_range if S(min_range) >= peak / 2 else optimize.brentq(lambda r: S(r) - peak / 2, min_range, arg)
    hi = top if S(top - 1e-9) >= peak / 2 else optimize.brentq(lambda r: S(r) - peak / 2, arg, top)
    return peak, lo, hi


@pytest.mark.parametrize("mor, start, full", [(60.0, 1.0, 10.0), (300.0, 0.5, 3.0)])
def test_the_fog_echo_table_matches_the_lidar_equation_by_quadrature(mor, start, full):
    rec = ReceiverParams(enabled=True, overlap_start_m=start, overlap_full_m=full)
    sensor = _ring(receiver=rec, weather=Weather(fog=FogParams(enabled=True, mor_m=mor)))
    model = WeatherModel(sensor)
    alpha = math.log(20.0) / mor
    peak, lo, hi = _soft_by_quadrature(rec, alpha, sensor.min_range_m)
    beta = 0.046 / mor
    assert model.fog.peak[-1] == pytest.approx(math.pi * beta * peak, rel=2e-3)
    assert model.fog.lo[-1] == pytest.approx(lo, abs=0.015)
    assert model.fog.hi[-1] == pytest.approx(hi, abs=0.015)
    # in front of a surface within the echo: the echo cut at the surface
    r0 = 0.5 * (lo + hi)
    peak_cut, lo_cut, hi_cut = _soft_by_quadrature(rec, alpha, sensor.min_range_m, r0)
    row = model.fog.row(np.array([r0]))[0]
    assert model.fog.r0[row] <= r0 < model.fog.r0[row] + 0.011
    assert model.fog.peak[row] == pytest.approx(math.pi * beta * peak_cut, rel=0.01)
    assert model.fog.hi[row] < r0 and model.fog.hi[row] == pytest.approx(hi_cut, abs=0.025)


def test_fog_returns_into_the_sky_come_at_the_rate_and_the_ranges_of_the_model():
    # Beams into the sky: the fog's echo (peak pi beta S_max) is detected when its Gamma-fluctuated power
    # (mean 1, relative std 0.5) reaches p_min, at a range uniform over its half-power span.
    rec = ReceiverParams(enabled=True, detection_range_m=30.0)
    mor = 60.0
    sensor = _ring(receiver=rec, weather=Weather(fog=FogParams(enabled=True, mor_m=mor)))
    peak, lo, hi = _soft_by_quadrature(rec, math.log(20.0) / mor, sensor.min_range_m)
    p_peak = math.pi * 0.046 / mor * peak
    sigma = 0.5
    expected = stats.gamma.sf(rec.min_power / p_peak, a=1 / sigma**2, scale=sigma**2)
    assert 0.2 < expected < 0.8  # a rate between none and every beam, so the test tells
    sim = SweepSimulator(_sky(), sensor, seed=4, motion_distortion=False)
    scans = [sim.sweep(_still(), 0.0, frame_index=k) for k in range(10)]
    beams = 10 * sensor.rays_per_sweep
    got = np.concatenate([s.range_m for s in scans])
    assert all(np.all(s.weather == FOG) for s in scans)
    assert abs(len(got) / beams - expected) < 4 * math.sqrt(expected * (1 - expected) / beams)
    assert lo - 0.011 <= got.min() and got.max() <= hi + 0.011
    ks = stats.kstest(got, stats.uniform(lo, hi - lo).cdf)
    assert ks.statistic < 1.63 / math.sqrt(len(got)) + 0.011 / (hi - lo)  # 1 % level, plus the table's step
    # no surface: the truth says so
    for s in scans:
        assert np.all(np.isnan(s.true_range_m)) and np.all(s.object_id == -1) and np.all(np.isnan(s.normal))


def test_fog_replaces_a_walls_return_as_often_as_its_echo_outshines_the_wall():
    # A wall at 60 m (beams within 8 deg of its normal): a beam reports the fog when the fluctuated fog echo
    # beats the wall's exp(-2 alpha R) rho cos / R^2 (strongest return); the expected count is the sum over
    # beams of the Gamma survival function at their power ratio.
    mor, rho, x = 400.0, 0.08, 60.0
    rec = ReceiverParams(enabled=True, detection_range_m=200.0)
    sensor = _ring(receiver=rec, weather=Weather(fog=FogParams(enabled=True, mor_m=mor)))
    v = np.array([[x, -9.0, -5.0], [x, 9.0, -5.0], [x, 9.0, 5.0], [x, -9.0, 5.0]])
    world = World(v, np.array([[0, 2, 1], [0, 3, 2]]), np.zeros(2), ["wall"], "wall", reflectance=np.array([rho]))
    sim = SweepSimulator(world, sensor, seed=6, motion_distortion=False)
    scans = [sim.sweep(_still(), 0.0, frame_index=k) for k in range(20)]
    alpha = math.log(20.0) / mor
    peak, _, _ = _soft_by_quadrature(rec, alpha, sensor.min_range_m)
    p_fog = math.pi * 0.046 / mor * peak
    az = np.radians(sensor.start_azimuth_deg - np.arange(sensor.columns_per_sweep) * sensor.azimuth_step_deg)
    on_wall = np.flatnonzero((np.cos(az) > 0) & (np.abs(np.tan(az)) * x < 9.0 - 0.05))
    cos = np.cos(az[on_wall])
    r = x / cos
    p_wall = rho * cos * np.exp(-2 * alpha * r) / r**2
    p_win = stats.gamma.sf(p_wall / p_fog, a=4.0, scale=0.25)
    fog = sum(int(np.sum(np.isin(s.azimuth_index[s.weather == FOG], on_wall))) for s in scans)
    walls = sum(int(np.sum(np.isin(s.azimuth_index[s.weather == SURFACE], on_wall))) for s in scans)
    mean, var = 20 * p_win.sum(), 20 * (p_win * (1 - p_win)).sum()
    assert 50 < mean < 20 * len(on_wall) - 50
    assert abs(fog - mean) < 4 * math.sqrt(var)
    assert walls + fog == 20 * len(on_wall)  # every beam on the wall returned something: the wall or the fog
    # a fog return in front of the wall keeps the wall as its truth
    s = scans[0]
    in_front = (s.weather == FOG) & np.isin(s.azimuth_index, on_wall)
    off_wall = np.flatnonzero((np.cos(az) <= 0) | (np.abs(np.tan(az)) * x > 9.05))
    sky = (s.weather == FOG) & np.isin(s.azimuth_index, off_wall)
    assert sky.sum() > 100 and np.all(np.isnan(s.true_range_m[sky]))  # the sky's: no surface behind
    np.testing.assert_allclose(s.true_range_m[in_front], x / np.cos(az[s.azimuth_index[in_front]]), rtol=1e-9)
    assert np.all(s.range_m[in_front] < s.true_range_m[in_front]) and np.all(s.object_id[in_front] == 0)


# ---------------------------------------------------------------- rain and snow
def _mu_by_quadrature(sensor: LidarModel, n0: float, lam: float, factor: float, rho: float, alpha: float):
    """mu(R) of detectable particles along a beam into the sky, by quadrature of the module's rate."""
    rec = sensor.receiver

    def rate(r):
        w = rec.beam_exit_diameter_m + r * math.radians(rec.footprint_divergence_deg)
        gain = rho * float(rec.overlap(r)) * math.exp(-2 * alpha * r)
        if gain <= 0:
            return 0.0
        d_min = w * r * math.sqrt(rec.min_power / gain)
        return 0.25 * math.pi * w**2 * n0 / lam * math.exp(-lam * 1e3 * d_min / factor) if d_min <= w else 0.0

    pts = [rec.overlap_start_m, rec.overlap_full_m]
    return lambda r: integrate.quad(rate, sensor.min_range_m, r, points=[p for p in pts if p < r] or None,
                                    limit=400)[0]


@pytest.mark.parametrize("kind", ["rain", "snow"])
def test_particle_returns_per_beam_match_the_rate_of_the_drop_size_distribution(kind):
    # near overlap and a sensitive receiver: enough particles to count
    rec = ReceiverParams(enabled=True, overlap_start_m=0.5, overlap_full_m=2.0,
                         detection_range_m=150.0 if kind == "rain" else 40.0)
    if kind == "rain":
        rate = 3.0
        weather = Weather(rain=RainParams(enabled=True, rate_mm_h=rate, drop_reflectance=0.05))
        n0, lam, factor, rho, code = 8000.0, 4.1 * rate**-0.21, 1.0, 0.05, RAIN
    else:
        rate = 0.5
        weather = Weather(snow=SnowParams(enabled=True, rate_mm_h=rate, flake_reflectance=0.2))
        n0, lam, factor, rho, code = 3800.0 * rate**-0.87, 2.55 * rate**-0.48, 2.15, 0.2, SNOW
    alpha = math.pi * factor**2 * n0 / lam**3 * 1e-6
    extinction, _ = integrate.quad(lambda d: n0 * math.exp(-lam * d) * 2 * math.pi * (factor * d) ** 2 / 4, 0, 50)
    assert alpha == pytest.approx(extinction * 1e-6, rel=1e-6)  # 2 x the geometric cross-section, per m
    sensor = _ring(receiver=rec, weather=weather, return_mode="first")
    assert WeatherModel(sensor).alpha == pytest.approx(alpha, rel=1e-12)
    mu = _mu_by_quadrature(sensor, n0, lam, factor, rho, alpha)
    total = mu(sensor.max_range_m)
    expected = 1 - math.exp(-total)
    assert 0.05 < expected < 0.7
    sim = SweepSimulator(_sky(), sensor, seed=8, motion_distortion=False)
    scans = [sim.sweep(_still(), 0.0, frame_index=k) for k in range(8)]
    beams = 8 * sensor.rays_per_sweep
    got = np.concatenate([s.range_m for s in scans])
    assert all(np.all(s.weather == code) for s in scans)
    assert abs(len(got) / beams - expected) < 4 * math.sqrt(expected * (1 - expected) / beams)
    # the nearest particle of a Poisson process along the beam: P(range <= R) = 1 - exp(-mu(R))
    grid = np.linspace(sensor.min_range_m, np.max(got) + 1.0, 120)
    F = np.array([1 - math.exp(-mu(r)) for r in grid]) / expected
    ks = stats.kstest(got, lambda r: np.interp(r, grid, F))
    assert ks.statistic < 1.63 / math.sqrt(len(got)) + 0.01


def test_particles_return_early_in_front_of_a_surface_and_keep_it_as_their_truth():
    rec = ReceiverParams(enabled=True, overlap_start_m=0.5, overlap_full_m=2.0, detection_range_m=40.0)
    sensor = _ring(receiver=rec, weather=Weather(snow=SnowParams(enabled=True, rate_mm_h=0.5)), return_mode="first")
    x = 20.0
    v = np.array([[x, -30.0, -5.0], [x, 30.0, -5.0], [x, 30.0, 5.0], [x, -30.0, 5.0]])
    world = World(v, np.array([[0, 2, 1], [0, 3, 2]]), np.zeros(2), ["wall"], "wall")
    scan = SweepSimulator(world, sensor, seed=1, motion_distortion=False).sweep(_still(), 0.0)
    behind = np.isfinite(scan.true_range_m)
    snow = (scan.weather == SNOW) & behind
    assert snow.sum() > 100 and (scan.weather == SURFACE).sum() > 100 and (~behind).sum() > 100
    assert np.all(scan.weather[~behind] == SNOW)  # beams past the wall's ends: snow or nothing
    assert np.all(scan.range_m[snow] < scan.true_range_m[snow])
    beam = scan.xyz[snow] / scan.range_m[snow, None]
    np.testing.assert_allclose(scan.true_xyz[snow][:, 0], x, atol=1e-9)  # the wall behind, on the same beam
    np.testing.assert_allclose(scan.true_xyz[snow], beam * scan.true_range_m[snow, None], atol=1e-9)


# ---------------------------------------------------------------- seeds, order, the truth on disk
def _weather_sensor() -> LidarModel:
    rec = ReceiverParams(enabled=True)
    return load_sensor("vlp16").with_overrides(
        receiver=rec, weather=Weather(fog=FogParams(enabled=True, mor_m=80.0),
                                      snow=SnowParams(enabled=True, rate_mm_h=1.0)))


def test_weather_is_seeded_and_independent_of_the_frame_order():
    from tests.helpers import box_room

    world, sensor = box_room(), _weather_sensor()
    a = SweepSimulator(world, sensor, seed=3, motion_distortion=False)
    b = SweepSimulator(world, sensor, seed=3, motion_distortion=False)
    first = [a.sweep(_still(), 0.1 * k, frame_index=k) for k in range(3)]
    second = [b.sweep(_still(), 0.1 * k, frame_index=k) for k in (2, 0, 1)]
    for s, t in zip(first, [second[1], second[2], second[0]], strict=True):
        np.testing.assert_array_equal(s.xyz, t.xyz)
        np.testing.assert_array_equal(s.weather, t.weather)
        np.testing.assert_array_equal(s.intensity, t.intensity)
    assert set(np.unique(first[0].weather)) == {SURFACE, FOG, SNOW}
    other = SweepSimulator(world, sensor, seed=4, motion_distortion=False).sweep(_still(), 0.0)
    assert not np.array_equal(other.weather, first[0].weather)


def test_the_truth_format_carries_the_weather_and_clear_sequences_stay_version_2(tmp_path):
    import json

    from simlidar.dataset import open_sequence
    from simlidar.formats import truth
    from simlidar.simulate import simulate_sequence
    from tests.helpers import box_room, constant_velocity

    world = box_room()
    traj = constant_velocity(v=(2.0, 0.0, 0.0), start=(-5.0, 0.0, 0.0))
    sensor = _weather_sensor()
    scans = []
    out = simulate_sequence(world, traj, sensor, tmp_path / "fog", frames=2, seed=1,
                            on_frame=lambda k, scan: scans.append(scan))
    seq = open_sequence(out)
    assert seq.manifest["format_version"] == 3 and seq.sensor == sensor
    for scan, frame in zip(scans, seq, strict=True):
        rec = frame.fields
        assert rec.dtype == truth.sidecar_dtype(weather=True)
        np.testing.assert_array_equal(rec["weather"], scan.weather)
        bare = np.isnan(scan.true_range_m)
        np.testing.assert_array_equal(np.isnan(rec["true_range_m"]), bare)
        np.testing.assert_array_equal(rec["object_id"], scan.object_id)
        ok = ~bare
        np.testing.assert_allclose(rec["true_xyz"][ok], scan.true_xyz[ok], atol=1e-4)
        assert np.all(np.isnan(rec["normal"][bare]))
    # the degeneracy figures describe what the sensor measured of the world: the surfaces
    assert (out / "degeneracy.csv").is_file()
    clear = simulate_sequence(world, traj, load_sensor("vlp16"), tmp_path / "clear", frames=1, seed=1)
    assert json.loads((clear / "manifest.json").read_text())["format_version"] == 2
    data = (clear / "sidecar" / "000000.truth").read_bytes()
    assert data[truth.BLOCKS_BYTE] == 0 and open_sequence(clear)[0].fields.dtype == truth.SIDECAR_DTYPE


# ---------------------------------------------------------------- the keys
def test_weather_keys_are_off_by_default_round_trip_and_fail_in_one_line(tmp_path):
    for name in ("vlp16", "salo32", "hdl64e", "os1-64"):
        d = load_sensor(name).to_dict()
        assert "receiver" not in d and "weather" not in d  # existing sensor files stay as they were
    on = _weather_sensor()
    on.save(tmp_path / "s.yaml")
    assert load_sensor_file(tmp_path / "s.yaml") == on
    assert set(on.to_dict()["weather"]) == {"fog", "snow"}
    data = load_sensor("vlp16").to_dict()
    with pytest.raises(SensorError, match=r"bad.yaml.*key 'receiver.enabled' is false, but weather \(fog\)"):
        from_dict({**data, "weather": {"fog": {"enabled": True}}}, origin=str(tmp_path / "bad.yaml"))
    for bad, key in (({"weather": {"fog": {"mor_m": -1}}}, "weather.fog.mor_m"),
                     ({"weather": {"rain": {"rate": 3}}}, "weather.rain.rate"),
                     ({"receiver": {"overlap_start_m": 5, "overlap_full_m": 2}}, "receiver.overlap_start_m"),
                     ({"weather": {"fog": True}}, "weather.fog")):
        with pytest.raises(SensorError, match=rf"bad.yaml.*key '{key}'") as info:
            from_dict({**data, **bad}, origin=str(tmp_path / "bad.yaml"))
        assert "\n" not in str(info.value)


def test_a_method_is_handed_neither_the_weather_nor_its_flags(tmp_path):
    from simlidar.dataset import open_sequence
    from simlidar.simulate import simulate_sequence
    from tests.helpers import box_room, constant_velocity
    from tools.staging import StagingError, check_fields, sensor_view, staged

    out = simulate_sequence(box_room(), constant_velocity(start=(-5.0, 0.0, 0.0)), _weather_sensor(),
                            tmp_path / "seq", frames=1, seed=0)
    seq = open_sequence(out)
    with staged(seq, fields=("ring", "time_s")) as st:
        handed = load_sensor_file(st.sensor)
        assert not handed.weather.on and handed.receiver == seq.sensor.receiver
        assert handed == seq.sensor.clear_air()
    with pytest.raises(StagingError, match="'weather' is the simulator's ground truth"):
        check_fields(("ring", "weather"))

    from simlidar.in_memory import simulate_in_memory

    mem = simulate_in_memory(box_room(), constant_velocity(start=(-5.0, 0.0, 0.0)), _weather_sensor(), 1,
                             fields="truth")
    assert "weather" in mem.fields[0].dtype.names
    view = sensor_view(mem, ("ring",))
    assert not view.sensor.weather.on and view.fields[0].dtype.names == ("ring",)
