"""What the poles stage keeps of the weather, against the truth: structure poles and weather "poles"; and the
weather's share of the points at the stages before it (the clean returns, the ICP's points, the map's).

Fog's backscatter, raindrops and snowflakes return from a random range on a beam, and near the
sensor each such return stands clear of its background: a pole by the pole rule. This tool runs
the odometry's own preparation (``odometry.preparation.prepare_scan``, the default configuration,
with ``poles.clutter_filter`` on and off) over consecutive scans of the weather suite and labels
every pole by the truth of its nearest return (a weather return or a surface's). It then feeds the
scans' poles, placed by the true poses, through the pole map (``odometry.poles.PoleMap``) to count
what the map's target holds once the confirmation by a neighbouring frame is asked for.

    python -m tools.pole_clutter --seeds 101 --frames 3 --out OUT [--real FOLDER=SENSOR ...]

prints a table per condition (scans the filter found cluttered, and the range over the scans of the
statistic that decides it: crowded one-return poles per 1000 beams fired; poles per scan: of
structure, of weather, and the shares the filter keeps; the target's poles after confirmation) and
writes ``OUT/pole_clutter.csv`` (a row per sequence and condition). ``--real`` adds real scans (no
truth: clear air as far as anyone knows) to check that the gate leaves a real street alone.
"""

from __future__ import annotations

import argparse
import csv
import io
import sys
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from scipy.spatial import KDTree

from odometry.config import DEFAULT_VARIANT, variant
from odometry.poles import PoleMap, WeatherGate
from odometry.preparation import prepare_scan
from scenes.families import FAMILIES
from simlidar import se3
from simlidar.formats.atomic import atomic_write_text
from simlidar.in_memory import simulate_in_memory
from tools.family_suite import TUNING_SEEDS, suite_world, weather_suite
from tools.weather_conditions import CONDITIONS

# The scans start this long after the sequence's start (the suite's sequences are placed in motion).
OFFSET_S = 3.0


@dataclass
class Counts:
    """Poles summed over a sequence's scans: all of them (``prepare_scan`` without the filter), what the filter
    keeps (with it; each scan's weather decided as the odometry decides it, ``WeatherGate``), and the pole
    map's target after the last scan with and without the confirmation."""

    scans: int = 0
    cluttered: int = 0
    structure: int = 0
    weather: int = 0
    isolated_structure: int = 0
    isolated_weather: int = 0
    target_structure: int = 0
    target_weather: int = 0
    confirmed_structure: int = 0
    confirmed_weather: int = 0
    # the scans' points at the stages before the poles (the default with the filter): the clean returns, the
    # ICP's points (voxel centroids past the NCF and curvature filters) and the voxel centroids the map takes
    clean: int = 0
    clean_weather: int = 0
    icp: int = 0
    icp_weather: int = 0
    mapped: int = 0
    mapped_weather: int = 0


def per_1000_beams(rates: list[float]) -> str:
    """min / median / max of the scans' crowded one-return poles per beam, per 1000 beams."""
    r = 1000.0 * np.asarray(rates)
    return f"{r.min():.2f} / {np.median(r):.2f} / {r.max():.2f}" if len(r) else "-"


def labelled_poles(frame, sensor, config, counts: Counts | None = None):
    """A frame's poles as the odometry's preparation finds them: (P, 3) sensor frame, m; (P,) bool, True where
    the nearest clean return is a weather return in the truth; the ``odometry.poles.Poles`` themselves.
    counts: add the frame's points at the stages before the poles to these (the normals then estimated)."""
    prepared = prepare_scan(frame.points, frame.time_s, frame.ring, config, sensor, with_normals=counts is not None,
                            with_poles=True)
    poles = prepared.scan.poles
    if frame.field("true_range_m") is None:
        raise ValueError("the frame has no per-return truth: simulate with fields='truth'")
    weather = frame.field("weather")  # absent in clear air: every return is a surface's
    weather = np.zeros(len(frame.points)) if weather is None else weather
    clean_weather = np.asarray(weather)[prepared.clean.kept_rows] > 0
    tree = KDTree(prepared.clean.points)
    if counts is not None:  # (a voxel centroid is labelled by its nearest clean return)
        counts.clean += len(clean_weather)
        counts.clean_weather += int(clean_weather.sum())
        for name, points in (("icp", prepared.scan.points), ("mapped", prepared.scan.centroids)):
            labels = clean_weather[tree.query(points)[1]] if len(points) else np.zeros(0, dtype=bool)
            setattr(counts, name, getattr(counts, name) + len(labels))
            setattr(counts, f"{name}_weather", getattr(counts, f"{name}_weather") + int(labels.sum()))
    if len(poles) == 0:
        return poles.points.reshape(0, 3), np.zeros(0, dtype=bool), poles
    _, nearest = tree.query(poles.points)
    return poles.points, clean_weather[nearest], poles


def _map_counts(poles_world: list[np.ndarray], labels: list[np.ndarray], cluttered: list[bool] | None
                ) -> tuple[int, int]:
    """(structure, weather) poles of the pole map's target after every scan's poles went in; cluttered: each
    scan's flag, with the confirmation asked for (None: without it)."""
    pole_map = PoleMap(frames_kept=len(poles_world), confirmed_only=cluttered is not None)
    for k, points in enumerate(poles_world):
        pole_map.add(points, cluttered is not None and cluttered[k])
    target = pole_map.target()
    if target is None:
        return 0, 0
    every, every_label = np.vstack(poles_world), np.concatenate(labels)
    _, row = KDTree(every).query(target.points)
    weather = int(every_label[row].sum())
    return len(target.points) - weather, weather


def count_sequence(spec, frames: int) -> tuple[Counts, list[float]]:
    """Counts over ``frames`` consecutive scans of a weather-suite sequence ``spec``, and each scan's crowded
    one-return poles per beam (``Poles.clutter_per_beam``)."""
    world, trajectory, sensor, start_s = suite_world(spec)
    seq = simulate_in_memory(world, trajectory, sensor, frames, seed=spec.seed, t_start=start_s + OFFSET_S,
                             fields="truth")
    on = variant(DEFAULT_VARIANT)
    off = replace(on, poles=replace(on.poles, clutter_filter=False))
    on = replace(on, poles=replace(on.poles, clutter_filter=True))
    c, gate = Counts(scans=len(seq)), WeatherGate()
    every, every_labels, isolated, isolated_labels, cluttered, rates = [], [], [], [], [], []
    for k in range(len(seq)):
        frame = seq[k]
        points, weather, _ = labelled_poles(frame, sensor, off)
        c.structure += int((~weather).sum())
        c.weather += int(weather.sum())
        every.append(se3.transform_points(seq.poses[k], points))
        every_labels.append(weather)
        points, weather, poles = labelled_poles(frame, sensor, on, counts=c)
        is_cluttered = gate.update(poles.clutter_per_beam)  # (as the odometry's predict stage decides)
        if is_cluttered:
            points, weather = points[~poles.suspect], weather[~poles.suspect]
        rates.append(poles.clutter_per_beam)
        c.cluttered += int(is_cluttered)
        c.isolated_structure += int((~weather).sum())
        c.isolated_weather += int(weather.sum())
        isolated.append(se3.transform_points(seq.poses[k], points))
        isolated_labels.append(weather)
        cluttered.append(is_cluttered)
    c.target_structure, c.target_weather = _map_counts(every, every_labels, None)
    c.confirmed_structure, c.confirmed_weather = _map_counts(isolated, isolated_labels, cluttered)
    return c, rates


def real_rates(folder: Path, sensor_name: str) -> tuple[int, list[float]]:
    """(scans cluttered, each scan's crowded one-return poles per beam) of a real sequence folder, read as the
    odometry reads it (no per-point times) with the default configuration."""
    from simlidar.dataset import open_sequence
    from simlidar.sensor import load_preset

    seq, sensor, config = open_sequence(folder, sensor=sensor_name), load_preset(sensor_name), variant(DEFAULT_VARIANT)
    cluttered, rates, gate = 0, [], WeatherGate()
    for k in range(len(seq)):
        poles = prepare_scan(seq[k].points, None, None, config, sensor, with_normals=False, with_poles=True).scan.poles
        cluttered += int(gate.update(poles.clutter_per_beam))
        rates.append(poles.clutter_per_beam)
    return cluttered, rates


def _share(part: int, whole: int) -> str:
    return f"{100.0 * part / whole:.1f} %" if whole else "-"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tools.pole_clutter", description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default=",".join(map(str, TUNING_SEEDS[:1])), help="comma-separated suite seeds")
    ap.add_argument("--families", default=",".join(FAMILIES), help="comma-separated families")
    ap.add_argument("--conditions", default=",".join(c for c in CONDITIONS if c != "clear"),
                    help="comma-separated weather conditions (clear included: the twins)")
    ap.add_argument("--frames", type=int, default=3, help="consecutive scans per sequence (the pole map's frames)")
    ap.add_argument("--out", type=Path, required=True, help="folder for pole_clutter.csv")
    ap.add_argument("--real", action="append", default=[], metavar="FOLDER=SENSOR",
                    help="a real sequence folder and its sensor preset (repeatable): its scans' gate statistic")
    args = ap.parse_args(argv)
    if args.frames < 1:
        ap.error("--frames must be at least 1")
    try:
        seeds = tuple(int(s) for s in args.seeds.split(","))
        specs = weather_suite(seeds, 200, tuple(args.families.split(",")), tuple(args.conditions.split(",")))
    except ValueError as exc:
        print(f"pole_clutter: {exc}", file=sys.stderr)
        return 2
    real = []
    for item in args.real:
        folder, _, sensor_name = item.partition("=")
        if not sensor_name or not Path(folder).is_dir():
            ap.error(f"--real {item}: expected FOLDER=SENSOR with an existing folder")
        real.append((Path(folder), sensor_name))
    rows, totals, rates = [], {}, {}
    for i, spec in enumerate(specs, 1):
        print(f"[{i}/{len(specs)}] {spec.family} seed {spec.seed} {spec.sensor} {spec.weather}", file=sys.stderr,
              flush=True)
        c, scan_rates = count_sequence(spec, args.frames)
        rates.setdefault(spec.weather, []).extend(scan_rates)
        rows.append({"family": spec.family, "seed": spec.seed, "sensor": spec.sensor, "condition": spec.weather,
                     **vars(c), "per_1000_beams_max": round(1000.0 * max(scan_rates), 3),
                     "per_1000_beams_min": round(1000.0 * min(scan_rates), 3)})
        t = totals.setdefault(spec.weather, Counts())
        for key, value in vars(c).items():
            setattr(t, key, getattr(t, key) + value)
    args.out.mkdir(parents=True, exist_ok=True)
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    atomic_write_text(args.out / "pole_clutter.csv", text.getvalue())
    print("| condition | scans | cluttered | gate: per 1000 beams, min / median / max | structure poles / scan "
          "| kept | weather poles / scan | kept | map target, weather (no filter) | map target, weather (filter) "
          "| structure in it |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for cond, t in totals.items():
        print(f"| {cond} | {t.scans} | {t.cluttered} | {per_1000_beams(rates[cond])} | {t.structure / t.scans:.1f} "
              f"| {_share(t.isolated_structure, t.structure)} "
              f"| {t.weather / t.scans:.1f} | {_share(t.isolated_weather, t.weather)} "
              f"| {_share(t.target_weather, t.target_weather + t.target_structure)} "
              f"| {_share(t.confirmed_weather, t.confirmed_weather + t.confirmed_structure)} "
              f"| {_share(t.confirmed_structure, t.target_structure)} |")
    for folder, sensor_name in real:
        cluttered, scan_rates = real_rates(folder, sensor_name)
        print(f"| real: {folder.name} ({sensor_name}) | {len(scan_rates)} | {cluttered} | {per_1000_beams(scan_rates)} "
              "| | | | | | | |")
    print("\nThe weather's share of a scan's points at the stages before the poles (the default's preparation):\n")
    print("| condition | clean returns / scan | weather in them | ICP points / scan | weather in them "
          "| the map's points / scan | weather in them |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for cond, t in totals.items():
        print(f"| {cond} | {t.clean / t.scans:.0f} | {_share(t.clean_weather, t.clean)} | {t.icp / t.scans:.0f} "
              f"| {_share(t.icp_weather, t.icp)} | {t.mapped / t.scans:.0f} | {_share(t.mapped_weather, t.mapped)} |")
    print(f"rows: {args.out / 'pole_clutter.csv'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
