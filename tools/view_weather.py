"""Pictures of the weather (``simlidar.weather``) and its checks' figures against the model's analytic expectations.

    python -m tools.view_weather --out out/weather     # the four PNGs below; the figures printed

- ``fog_attenuation.png``: the return rate against range of tiles at normal incidence, reflectance uniform
  in (0, 1), in clear air and in fog of three visibilities (backscatter off), beside
  ``1 - min(1, p_min R^2 exp(2 alpha R))``: far and dark surfaces drop first, the fog's exp(-2 alpha R)
  pulling the cut in;
- ``fog_backscatter.png``: the fog's echo against reported range (the lidar equation's integral) for three
  visibilities, and the ranges of the fog returns of beams into the sky against the model's half-power span,
  with the rate at which they are detected against the Gamma fluctuation's survival function;
- ``particle_returns.png``: rain and snow returns per beam into the sky against the rate ``1 - exp(-mu)`` of
  the drop-size distribution, over precipitation intensity, for the default receiver and a near-sighted one;
- ``weather_scans.png``: one salo32 sweep in the city, top-down, in clear air and in each weather, the
  weather's returns coloured by kind;
- ``overlap_sensitivity.csv``: how much the receiver's near-range overlap (a default of ours) decides: the
  share of that sweep's beams returning weather with the overlap full at 5 m and at 10 m;
- ``suite_conditions.csv`` (``--only suite``, minutes): one sweep of every evaluation sequence of the weather
  suite in each condition, its surface returns against the clear twin's and its share of weather returns.

Each check simulates beams (``SweepSimulator``) and sets what it counts beside what the model's equations
say (computed here from ``simlidar.weather``'s closed forms and tables); the test suite asserts the same
against independent quadratures (``tests/test_weather.py``).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

KIND_COLOURS = {1: ("fog", "C0"), 2: ("rain", "C2"), 3: ("snow", "C3")}


def _still():
    from simlidar.trajectory import SampledTrajectory

    return SampledTrajectory(np.array([0.0]), np.eye(4)[None])


def _ring(**keys):
    """One level ring, 0.1 deg columns (3600 beams), no noise."""
    from simlidar.sensor import LidarModel

    return LidarModel(name="ring", vertical_angles_deg=(0.0,), azimuth_step_deg=0.1, rotation_hz=10.0,
                      range_noise_std_m=0.0, min_range_m=0.5, max_range_m=250.0, start_azimuth_deg=0.0, **keys)


def _sky():
    from simlidar.world import World

    return World(np.array([[0.0, 0.0, -500.0], [1.0, 0.0, -500.0], [0.0, 1.0, -500.0]]), np.array([[0, 1, 2]]),
                 np.zeros(1), ["ground"], "sky")


def _tiles(ranges: np.ndarray, reflectance: np.ndarray, sensor):
    """A small tile facing the sensor across each column's beam at ``ranges[c]``, reflectance ``reflectance[c]``."""
    from simlidar.world import World

    az = sensor.column_azimuth_rad(np.arange(len(ranges)))
    half = np.radians(0.04) * ranges
    d = np.column_stack([np.cos(az), np.sin(az), np.zeros_like(az)])
    side = np.column_stack([-np.sin(az), np.cos(az), np.zeros_like(az)])
    up = np.array([0.0, 0.0, 1.0])
    c = d * ranges[:, None]
    h = half[:, None]
    corners = np.stack([c - side * h - up * h, c + side * h - up * h, c + side * h + up * h, c - side * h + up * h],
                       axis=1)
    base = 4 * np.arange(len(ranges))[:, None]
    faces = np.concatenate([base + [0, 2, 1], base + [0, 3, 2]])
    ids = np.concatenate([np.arange(len(ranges))] * 2)
    return World(corners.reshape(-1, 3), faces, ids, ["wall"] * len(ranges), "tiles", reflectance=reflectance)


def fog_attenuation(out: Path) -> Path:
    """Return rate against range of tiles of uniform reflectance, clear air and fog, with the analytic rate."""
    import matplotlib.pyplot as plt

    from simlidar.sweep import SweepSimulator
    from simlidar.weather import FogParams, ReceiverParams, Weather

    rng = np.random.default_rng(5)
    frames, n = 6, 3600
    rec = ReceiverParams(enabled=True)
    edges = np.arange(10.0, 201.0, 10.0)
    mid = 0.5 * (edges[1:] + edges[:-1])
    fig, ax = plt.subplots(figsize=(8, 5))
    print("fog attenuation: return rate of tiles (reflectance U(0, 1), normal incidence) against range, "  # noqa: T201
          f"{frames} x {n} tiles a visibility; detection_range_m {rec.detection_range_m:g}")
    for k, mor in enumerate((None, 600.0, 200.0, 80.0)):
        weather = Weather() if mor is None else Weather(fog=FogParams(enabled=True, mor_m=mor, beta_times_mor=0.0))
        sensor = _ring(receiver=rec, weather=weather)
        ranges, rho, seen = [], [], []
        for f in range(frames):
            r_, p_ = rng.uniform(10.0, 200.0, n), rng.uniform(0.0, 1.0, n)
            scan = SweepSimulator(_tiles(r_, p_, sensor), sensor, seed=f, motion_distortion=False).sweep(_still(), 0.0)
            got = np.zeros(n, bool)
            got[scan.azimuth_index] = True
            ranges.append(r_), rho.append(p_), seen.append(got)
        ranges, seen = np.concatenate(ranges), np.concatenate(seen)
        alpha = 0.0 if mor is None else math.log(20.0) / mor
        rate = np.array([seen[(ranges >= lo) & (ranges < hi)].mean() for lo, hi in zip(edges[:-1], edges[1:],
                                                                                        strict=True)])
        count = np.array([((ranges >= lo) & (ranges < hi)).sum() for lo, hi in zip(edges[:-1], edges[1:],
                                                                                    strict=True)])
        rr = np.linspace(10.0, 200.0, 400)
        model = 1.0 - np.minimum(1.0, rec.min_power * rr**2 * np.exp(2 * alpha * rr))
        expect = np.array([np.mean(1 - np.minimum(1, rec.min_power * g**2 * np.exp(2 * alpha * g)))
                           for g in (np.linspace(lo, hi, 101) for lo, hi in zip(edges[:-1], edges[1:], strict=True))])
        sd = np.sqrt(np.maximum(expect * (1 - expect), 1e-12) / count)
        worst = np.max(np.abs(rate - expect) / np.maximum(sd, 1e-9))
        label = "clear air" if mor is None else f"fog, MOR {mor:g} m"
        print(f"  {label:18s} max |measured - expected| over 10 m bins {np.max(np.abs(rate - expect)):.4f} "  # noqa: T201
              f"({worst:.2f} binomial sigma); rate at 50 m {np.interp(50, mid, rate):.3f}, 100 m "
              f"{np.interp(100, mid, rate):.3f}")
        ax.plot(mid, rate, "o", color=f"C{k}", label=f"{label}: simulated")
        ax.plot(rr, model, color=f"C{k}", lw=1, label=f"1 - min(1, p_min R² exp(2·{alpha:.4f}·R))")
    ax.set_xlabel("range of the tile, m")
    ax.set_ylabel("share of tiles returned")
    ax.set_title("Fog: far and dark surfaces drop first (p_min: a 10 % target at 100 m)", fontsize=10)
    ax.legend(fontsize=7, ncol=2)
    ax.grid(alpha=0.3)
    path = out / "fog_attenuation.png"
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def fog_backscatter(out: Path) -> Path:
    """The fog's echo against reported range, and the sky beams' fog returns against the half-power span."""
    import matplotlib.pyplot as plt
    from scipy import stats

    from simlidar.sweep import SweepSimulator
    from simlidar.weather import SPEED_OF_LIGHT_M_S, FogParams, ReceiverParams, Weather, WeatherModel, soft_response

    rec = ReceiverParams(enabled=True)
    fig, (ax, hist) = plt.subplots(1, 2, figsize=(13, 4.8))
    rep = np.linspace(0.5, 15.0, 600)
    half = 0.5 * SPEED_OF_LIGHT_M_S * rec.pulse_width_s
    print("fog backscatter: beams into the sky, 10 sweeps x 3600 beams a visibility")  # noqa: T201
    for k, mor in enumerate((60.0, 200.0, 800.0)):
        sensor = _ring(receiver=rec, weather=Weather(fog=FogParams(enabled=True, mor_m=mor)))
        model = WeatherModel(sensor)
        p = math.pi * sensor.weather.fog.beta_per_m_sr * soft_response(rec, model.alpha, rep + half, np.inf)
        ax.plot(rep, p / rec.min_power, color=f"C{k}", label=f"MOR {mor:g} m")
        lo, hi = model.fog.lo[-1], model.fog.hi[-1]
        ax.axvspan(lo, hi, color=f"C{k}", alpha=0.08)
        sim = SweepSimulator(_sky(), sensor, seed=k, motion_distortion=False)
        got = np.concatenate([sim.sweep(_still(), 0.0, frame_index=f).range_m for f in range(10)])
        beams = 10 * sensor.rays_per_sweep
        sigma = sensor.weather.fog.backscatter_fluctuation
        expect = stats.gamma.sf(rec.min_power / model.fog.peak[-1], a=1 / sigma**2, scale=sigma**2)
        ks = stats.kstest(got, stats.uniform(lo, hi - lo).cdf).statistic
        print(f"  MOR {mor:5g} m: peak {model.fog.peak[-1] / rec.min_power:6.2f} x p_min; beams with a fog return "  # noqa: T201
              f"{len(got) / beams:.4f}, expected {expect:.4f} (binomial sigma "
              f"{math.sqrt(expect * (1 - expect) / beams):.4f}); ranges {got.min():.2f}..{got.max():.2f} m, "
              f"span {lo:.2f}..{hi:.2f} m, KS distance to uniform {ks:.4f} (1 % level "
              f"{1.63 / math.sqrt(max(len(got), 1)):.4f})")
        hist.hist(got, bins=np.arange(0.5, 9.0, 0.1), density=True, histtype="step", color=f"C{k}",
                  label=f"MOR {mor:g} m: {100 * len(got) / beams:.1f} % of beams (model {100 * expect:.1f} %)")
        hist.plot([lo, lo, hi, hi], [0, 1 / (hi - lo), 1 / (hi - lo), 0], color=f"C{k}", lw=0.8, ls="--")
    ax.axhline(1.0, color="k", lw=0.6, ls=":")
    ax.set_xlabel("reported range, m")
    ax.set_ylabel("fog echo / p_min")
    ax.set_yscale("log")
    ax.set_title("The fog's echo, π β S(R) (overlap 1 → 10 m, τ_H 20 ns); shaded: half-power span", fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    hist.set_xlabel("range of the fog returns of beams into the sky, m")
    hist.set_ylabel("density")
    hist.set_title("Simulated (steps) against the model's uniform half-power span (dashed)", fontsize=10)
    hist.legend(fontsize=8)
    hist.grid(alpha=0.3)
    path = out / "fog_backscatter.png"
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def particle_returns(out: Path) -> Path:
    """Rain and snow returns per beam into the sky against 1 - exp(-mu), over precipitation intensity."""
    import matplotlib.pyplot as plt

    from simlidar.sweep import SweepSimulator
    from simlidar.weather import RainParams, ReceiverParams, SnowParams, Weather, WeatherModel

    receivers = {"default receiver": ReceiverParams(enabled=True),
                 "overlap 0.5 → 2 m": ReceiverParams(enabled=True, overlap_start_m=0.5, overlap_full_m=2.0)}
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.8))
    print("rain and snow: returns per beam into the sky (4 sweeps x 3600 beams) against 1 - exp(-mu)")  # noqa: T201
    for ax, kind, rates in ((axes[0], "rain", (1.0, 3.0, 10.0, 30.0, 100.0)),
                            (axes[1], "snow", (0.01, 0.03, 0.1, 0.3, 1.0, 3.0))):
        for j, (name, rec) in enumerate(receivers.items()):
            measured, expected, sigma = [], [], []
            for i, rate in enumerate(rates):
                section = RainParams(enabled=True, rate_mm_h=rate) if kind == "rain" else \
                    SnowParams(enabled=True, rate_mm_h=rate)
                sensor = _ring(receiver=rec, weather=Weather(**{kind: section}))
                mu = WeatherModel(sensor).particles[0].cumulative[-1]
                sim = SweepSimulator(_sky(), sensor, seed=100 * j + i, motion_distortion=False)  # independent draws
                beams = 4 * sensor.rays_per_sweep
                got = sum(len(sim.sweep(_still(), 0.0, frame_index=f)) for f in range(4)) / beams
                e = 1 - math.exp(-mu)
                measured.append(got), expected.append(e), sigma.append(math.sqrt(max(e * (1 - e), 1e-12) / beams))
                print(f"  {kind} {rate:6g} mm/h, {name:17s}: {got:.5f} of beams, expected {e:.5f} "  # noqa: T201
                      f"(binomial sigma {sigma[-1]:.5f})")
            m, e2 = np.array(measured), 2 * np.array(sigma)
            ax.errorbar(rates, np.maximum(m, 1e-5), yerr=[np.minimum(e2, m - 1e-5 * (m > 1e-5)), e2], fmt="o",
                        color=f"C{j}", label=f"{name}: simulated (2 sigma)")
            ax.plot(rates, expected, color=f"C{j}", lw=1, label=f"{name}: 1 - exp(-mu)")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_ylim(1e-5, 1.5)
        ax.set_xlabel(f"{kind} intensity, mm/h" + (" (melted)" if kind == "snow" else ""))
        ax.set_ylabel("share of beams with a particle return")
        ax.set_title(f"{kind.capitalize()} ({'Marshall-Palmer' if kind == 'rain' else 'Gunn-Marshall'} sizes)",
                     fontsize=10)
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    path = out / "particle_returns.png"
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


WEATHERS = {
    "clear air": {},
    "light fog, MOR 800 m": {"fog": {"enabled": True, "mor_m": 800.0}},
    "dense fog, MOR 60 m": {"fog": {"enabled": True, "mor_m": 60.0}},
    "rain, 20 mm/h": {"rain": {"enabled": True, "rate_mm_h": 20.0}},
    "snow, 1.5 mm/h": {"snow": {"enabled": True, "rate_mm_h": 1.5}},
}


def weather_scans(out: Path, sensor_name: str = "salo32") -> Path:
    """One sweep in the city, top-down, in clear air and in each weather."""
    import matplotlib.pyplot as plt

    from simlidar.sensor import load_sensor
    from simlidar.sweep import SweepSimulator
    from simlidar.weather import ReceiverParams, Weather
    from tools.worlds import build_scene_world

    scene = build_scene_world("city", 3, {})
    base = load_sensor(sensor_name).with_overrides(receiver=ReceiverParams(enabled=True))
    fig, axes = plt.subplots(1, len(WEATHERS), figsize=(4.2 * len(WEATHERS), 4.6))
    print(f"one {sensor_name} sweep of city seed 3 at 20 s in each weather:")  # noqa: T201
    for ax, (name, keys) in zip(axes, WEATHERS.items(), strict=True):
        sensor = base.with_overrides(weather=Weather.from_dict(keys))
        scan = SweepSimulator(scene.world, sensor, seed=3).sweep(scene.trajectory, 20.0, frame_index=1)
        kind = scan.weather if scan.weather is not None else np.zeros(len(scan), np.uint8)
        near = (np.abs(scan.xyz[:, 0]) < 40) & (np.abs(scan.xyz[:, 1]) < 40)
        surface = near & (kind == 0)
        ax.scatter(scan.xyz[surface, 1], scan.xyz[surface, 0], s=0.15, color="0.45", rasterized=True)
        counts = []
        for code, (label, colour) in KIND_COLOURS.items():
            sel = near & (kind == code)
            if sel.any():
                ax.scatter(scan.xyz[sel, 1], scan.xyz[sel, 0], s=0.4, color=colour, rasterized=True, label=label)
            if (kind == code).any():
                counts.append(f"{label} {int((kind == code).sum()):,}")
        surf_all = kind == 0
        far = np.percentile(scan.range_m[surf_all], 95) if surf_all.any() else float("nan")
        print(f"  {name:22s} {len(scan):7,} returns: surface {int(surf_all.sum()):7,}"  # noqa: T201
              f"{', ' + ', '.join(counts) if counts else ''}; surface range 95th percentile {far:.1f} m")
        ax.set_title(f"{name}\n{int(surf_all.sum()):,} surface" + (f", {', '.join(counts)}" if counts else ""),
                     fontsize=9)
        ax.set_aspect("equal")
        ax.set_xlim(40, -40)
        ax.set_ylim(-40, 40)
        ax.set_xticks([-40, -20, 0, 20, 40])
        if counts:
            ax.legend(fontsize=7, markerscale=12, loc="lower left")
    axes[0].set_ylabel("x (ahead), m")
    for ax in axes:
        ax.set_xlabel("y (left), m")
    fig.suptitle(f"One {sensor_name} sweep, city seed 3, top-down within 40 m (grey: surfaces; receiver: a 10 % "
                 "target detected at 100 m)", fontsize=10)
    fig.tight_layout()
    path = out / "weather_scans.png"
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def overlap_sensitivity(out: Path, sensor_name: str = "salo32") -> Path:
    """The share of a city sweep's beams returning weather, with the receiver's overlap full at 5 m and at 10 m
    (printed; the file written is a CSV of the same)."""
    from simlidar.sensor import load_sensor
    from simlidar.sweep import SweepSimulator
    from simlidar.weather import ReceiverParams, Weather
    from tools.worlds import build_scene_world

    scene = build_scene_world("city", 3, {})
    runs = [("fog", "mor_m", v) for v in (50.0, 100.0, 300.0, 1000.0)] + \
        [("rain", "rate_mm_h", v) for v in (2.0, 10.0, 30.0)] + [("snow", "rate_mm_h", v) for v in (0.5, 1.0, 3.0)]
    lines = ["overlap_full_m,weather,key,value,weather_beam_share"]
    print(f"share of one {sensor_name} sweep's beams returning weather (city seed 3 at 20 s):")  # noqa: T201
    for full in (5.0, 10.0):
        rec = ReceiverParams(enabled=True, overlap_full_m=full)
        shares = []
        for section, key, value in runs:
            sensor = load_sensor(sensor_name).with_overrides(
                receiver=rec, weather=Weather.from_dict({section: {"enabled": True, key: value}}))
            scan = SweepSimulator(scene.world, sensor, seed=3).sweep(scene.trajectory, 20.0, frame_index=1)
            share = float((scan.weather > 0).sum()) / sensor.rays_per_sweep
            shares.append(f"{section} {value:g}: {100 * share:.1f} %")
            lines.append(f"{full:g},{section},{key},{value:g},{share:.5f}")
        print(f"  overlap full at {full:g} m: " + ", ".join(shares))  # noqa: T201
    path = out / "overlap_sensitivity.csv"
    path.write_text("\n".join(lines) + "\n")
    return path


def suite_conditions(out: Path) -> Path:
    """One sweep (frame 50, 5 s after the start) of every evaluation sequence of the weather suite in each
    condition: surface returns against the clear twin's and the share of weather returns (a CSV, and the
    summary per condition printed). About 70 sweeps and 14 scenes built: minutes."""
    from simlidar.sweep import SweepSimulator
    from tools.family_suite import EVALUATION_SEEDS, suite, suite_world
    from tools.weather_conditions import CONDITIONS, draw, sensor_in

    lines = ["family,seed,sensor,condition,drawn,returns,surface,surface_over_twin,weather_share"]
    summary: dict[str, list[tuple[float, float]]] = {c: [] for c in CONDITIONS}
    for base in suite(EVALUATION_SEEDS, kinds=("simulated",)):
        world, trajectory, sensor, start = suite_world(base)
        twin = None
        for condition in CONDITIONS:
            scan = SweepSimulator(world, sensor_in(sensor, condition, base.family, base.seed), seed=base.seed).sweep(
                trajectory, start + 5.0, frame_index=50)
            kind = scan.weather if scan.weather is not None else np.zeros(len(scan), np.uint8)
            surface = int((kind == 0).sum())
            twin = surface if condition == "clear" else twin
            drawn = " ".join(f"{k}={v}" for sec in draw(condition, base.family, base.seed).values()
                             for k, v in sec.items() if k != "enabled")
            share = float((kind > 0).mean())
            summary[condition].append((surface / twin, share))
            lines.append(f"{base.family},{base.seed},{base.sensor},{condition},{drawn},{len(scan)},{surface},"
                         f"{surface / twin:.4f},{share:.4f}")
    print("weather suite, evaluation seeds, one sweep a sequence: surface returns / the twin's, weather share")  # noqa: T201
    for condition, values in summary.items():
        a = np.array(values)
        print(f"  {condition:10s} {a[:, 0].mean():.2f} ({a[:, 0].min():.2f}..{a[:, 0].max():.2f})   "  # noqa: T201
              f"{100 * a[:, 1].mean():.1f} % ({100 * a[:, 1].min():.1f}..{100 * a[:, 1].max():.1f})")
    path = out / "suite_conditions.csv"
    path.write_text("\n".join(lines) + "\n")
    return path


def main(argv: list[str] | None = None) -> None:
    import matplotlib

    matplotlib.use("Agg")
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("out/weather"), help="folder for the PNGs (default out/weather)")
    ap.add_argument("--only", choices=("attenuation", "backscatter", "particles", "scans", "overlap", "suite"),
                    action="append", help="make only these (repeatable; suite: not by default, minutes)")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    makers = {"attenuation": fog_attenuation, "backscatter": fog_backscatter, "particles": particle_returns,
              "scans": weather_scans, "overlap": overlap_sensitivity}
    makers_all = {**makers, "suite": suite_conditions}
    for name in args.only or makers:
        print(makers_all[name](args.out))  # noqa: T201 - a script that reports what it wrote


if __name__ == "__main__":
    main()
