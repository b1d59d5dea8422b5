"""One self-contained HTML page of a sequence and the runs over it: scans in 3D, trajectories, error along the path.

``salo view SOURCE --html PAGE`` (a sequence folder, with ``--run`` poses files; or
a bench's output folder, a page per sequence) writes it. The page needs no network
and no server: it opens from disk in a browser with WebGL2 (Chromium, Firefox,
Safari 15+) and holds

- the scans, a frame slider and play, each scan placed by the truth's pose or by a
  method's own (two views side by side to compare), the previous few scans as a trail;
- the true trajectory and each method's, in the first scan's frame;
- points coloured by ring, intensity, height, the truth's object class (a simulated
  sequence's sidecar), or kept / dropped by our odometry's filters (recomputed from the
  run's configuration: range limits, voxel grid, normal-covariance and curvature
  filters, on the scan as measured). The simulator's worlds are static, so no point is
  moving; a ``moving`` per-point field, where a sequence has one, colours moving / static;
- each method's position error per frame against the truth, the truth's weakly
  constrained frames shaded, a cursor at the frame shown (click to go there).

Why a small WebGL2 viewer of our own (``view_html.js``, ~22 kB) and not a library:
pyvista's HTML export needs a trame/panel stack and writes one static mesh (no frames);
a rerun recording needs the rerun viewer (tens of MB of WebAssembly) and is not one
file; three.js would add ~600 kB and draws points no faster than a plain point shader.
The viewer draws 100k points a frame with one draw call per scan.

Encoding (what keeps a 64-ring sequence's page small): per frame, the points in the
lidar frame as int16 at ``QUANTUM_M`` (2 cm; points beyond +-655 m are left out),
ring by ring, each axis stored as differences between consecutive points (along
a ring, neighbours in azimuth are close), then ring, intensity (uint8), class and kept bits,
each frame zlib-compressed and base64-encoded; the page inflates a frame when it is
first shown (``DecompressionStream``), so opening it does not wait for every frame.
"""

from __future__ import annotations

import base64
import json
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from simlidar.formats.atomic import atomic_write_text

QUANTUM_M = 0.02  # the simulated range noise's size: invisible on screen, and a third smaller than 1 cm
LIMIT_M = 32767 * QUANTUM_M
ASSETS = Path(__file__).with_name("view_html.js")
TRUTH_COLOUR = "#222222"
TRACK_COLOURS = ("#1b4f9c", "#d95f02", "#1b9e77", "#7570b3", "#e7298a", "#66a61e", "#a6761d", "#444444")


class PageError(ValueError):
    """A page cannot be made from what was given; the message names the file and what is wrong."""


@dataclass
class Track:
    """One method's run over the sequence.

    label: its name. poses: (N, 4, 4) ``T_first_lidar`` (NaN after a divergence). weak: (N,) bool,
    the frames it flagged itself, or None. kept: per frame an (n_k,) bool of the shown points its
    filters kept, or None. colour: CSS colour.
    """

    label: str
    poses: np.ndarray
    weak: np.ndarray | None = None
    kept: list | None = None
    colour: str = ""


@dataclass
class PageData:
    """What a page shows.

    points: per frame (n_k, 3) float, lidar frame, m. ring, intensity, object_class, moving: per frame
    (n_k,) arrays or None. truth: (N, 4, 4) ``T_first_lidar`` or None. truth_weak: (N,) bool or None.
    times: (N,) sweep starts, s. classes: the names of ``object_class``'s values. tracks: the methods.
    """

    title: str
    points: list
    times: np.ndarray
    truth: np.ndarray | None = None
    truth_weak: np.ndarray | None = None
    ring: list | None = None
    intensity: list | None = None
    object_class: list | None = None
    moving: list | None = None
    classes: list[str] = field(default_factory=list)
    rings: int = 0
    tracks: list[Track] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    frame_numbers: np.ndarray | None = None


# ---------------------------------------------------------------- gathering
def read_poses_file(path: Path, frames: int | tuple[int, ...]) -> np.ndarray:
    """A KITTI poses file (NaN rows allowed: a method that diverged) as (N, 4, 4); PageError naming it.

    frames: the number of poses expected (or the numbers allowed: a whole sequence's, a selection's)."""
    try:
        rows = np.loadtxt(path, ndmin=2)
    except (OSError, ValueError) as exc:
        raise PageError(f"{path}: cannot read KITTI poses ({exc})") from None
    if rows.shape[1] != 12:
        raise PageError(f"{path}: expected 12 numbers a line (a KITTI pose), got {rows.shape[1]}")
    allowed = (frames,) if isinstance(frames, int) else tuple(frames)
    if len(rows) not in allowed:
        raise PageError(f"{path}: {len(rows)} poses, the sequence has {allowed[0]} frames"
                        + (f" ({allowed[1]} selected)" if len(allowed) > 1 and allowed[1] != allowed[0] else ""))
    poses = np.tile(np.eye(4), (len(rows), 1, 1))
    poses[:, :3, :4] = rows.reshape(-1, 3, 4)
    return poses


def _thin(n: int, max_points: int | None) -> np.ndarray | None:
    """Indices of at most ``max_points`` of ``n`` points, evenly spread in firing order (None: all)."""
    if max_points is None or n <= max_points:
        return None
    return np.linspace(0, n - 1, max_points).round().astype(np.int64)


def kept_by_filters(points: np.ndarray, ring: np.ndarray | None, config, sensor) -> np.ndarray:
    """(n,) bool: the points of a scan (n, 3), lidar frame, that our odometry's filters keep under ``config``:
    inside the range limits, in a voxel whose centroid the normal-covariance and curvature filters keep."""
    from odometry.filters import filter_scan
    from odometry.voxels import voxel_keys

    r = np.linalg.norm(points, axis=1)
    inside = np.isfinite(r) & (r >= config.clean.min_range_m) & (r <= config.clean.max_range_m)
    keep = np.zeros(len(points), dtype=bool)
    if inside.sum() < 3:
        return keep
    raw = points[inside]
    scan = filter_scan(raw, config, None if ring is None else ring[inside], sensor, with_normals=True)
    size = config.filter.voxel_size_m
    keep[inside] = np.isin(voxel_keys(raw, size), voxel_keys(scan.points, size))  # a centroid is in its voxel
    return keep


def sequence_page(folder: str | Path, runs: dict | None = None, *, frames: slice | None = None,
                  max_points: int | None = None, configs: dict | None = None, title: str = "",
                  on_frame=None) -> PageData:
    """A sequence (a folder ``simlidar.dataset.open_sequence`` reads) and runs over it, as a page's data.

    runs: label -> poses file (KITTI, one line per frame of the sequence; NaN rows: diverged) or
    (N, 4, 4) array. configs: label -> our ``OdometryConfig`` of that run (its kept / dropped points).
    frames: a slice of the frames to show. max_points: per frame, at most this many points (evenly
    thinned). on_frame(k) as frames are read. Raises PageError (a bad poses file), DatasetError.
    """
    from simlidar.dataset import open_sequence
    from simlidar.sequence import sweep_start_times

    folder = Path(folder)
    seq = open_sequence(folder)
    n = len(seq)
    index = np.arange(n)[frames if frames is not None else slice(None)]
    if len(index) == 0:
        raise PageError(f"{folder}: no frames selected")
    truth = None if seq.poses is None else np.asarray(seq.poses)
    tracks = []
    for i, (label, source) in enumerate((runs or {}).items()):
        poses = source if isinstance(source, np.ndarray) else read_poses_file(Path(source), (n, len(index)))
        weak = None if isinstance(source, np.ndarray) else _own_weak(Path(source), len(poses))
        if len(poses) != n:  # a run over the selected frames only: spread over the sequence's numbering
            whole = np.full((n, 4, 4), np.nan)
            whole[index] = poses
            poses = whole
            if weak is not None:
                spread = np.zeros(n, dtype=bool)
                spread[index] = weak
                weak = spread
        tracks.append(Track(label, poses, weak, None, TRACK_COLOURS[i % len(TRACK_COLOURS)]))
    manifest = getattr(seq, "manifest", None) or {}
    classes, class_of_object = _classes(manifest)
    data = PageData(title or folder.name, [], np.asarray(sweep_start_times(seq))[index],
                    frame_numbers=index, rings=int(getattr(seq.sensor, "rings", 0) or 0))
    ring, intensity, object_class, moving = [], [], [], []
    kept = {t.label: [] for t in tracks if (configs or {}).get(t.label) is not None}
    for k in index:
        frame = seq[int(k)]
        pick = _thin(len(frame.points), max_points)
        if frame.ring is not None:  # ring by ring: consecutive points are neighbours, their differences small
            order = np.argsort(np.asarray(frame.ring), kind="stable")
            pick = order if pick is None else order[np.isin(order, pick)]
        take = (lambda a: a) if pick is None else (lambda a, pick=pick: a[pick])
        pts = np.asarray(frame.points, dtype=np.float64)
        data.points.append(take(pts))
        ring.append(None if frame.ring is None else take(np.asarray(frame.ring)))
        intensity.append(None if frame.intensity is None else take(np.asarray(frame.intensity)))
        obj = frame.field("object_id")
        object_class.append(None if obj is None or class_of_object is None else
                            take(class_of_object[np.clip(np.asarray(obj), 0, len(class_of_object) - 1)]))
        mov = frame.field("moving")
        moving.append(None if mov is None else take(np.asarray(mov).astype(bool)))
        for label in kept:
            kept[label].append(take(kept_by_filters(pts, None if frame.ring is None else np.asarray(frame.ring),
                                                    configs[label], seq.sensor)))
        if on_frame is not None:
            on_frame(int(k))
    data.ring = ring if all(r is not None for r in ring) else None
    data.intensity = intensity if all(x is not None for x in intensity) else None
    data.object_class = object_class if all(x is not None for x in object_class) else None
    data.moving = moving if all(x is not None for x in moving) else None
    data.classes = classes if data.object_class is not None else []
    if truth is not None:
        data.truth = truth[index]
        data.truth = np.linalg.inv(data.truth[0]) @ data.truth
        if (folder / "degeneracy.csv").is_file():
            from tools.degenerate import truth_constraints

            data.truth_weak = truth_constraints(folder).weak[index]
    for t in tracks:
        t.poses = t.poses[index]
        if np.all(np.isfinite(t.poses[0])):
            t.poses = np.linalg.inv(t.poses[0]) @ t.poses
        t.weak = None if t.weak is None else t.weak[index]
        t.kept = kept.get(t.label)
    data.tracks = tracks
    if max_points is not None:
        data.notes.append(f"at most {max_points} points a frame shown (evenly thinned)")
    return data


def _own_weak(poses_file: Path, n: int) -> np.ndarray | None:
    """The frames a run flagged itself, from its diagnostics beside the poses (``NAME_diagnostics.csv``, or
    ``diagnostics.csv`` in a run folder of its own), or None."""
    from tools.degenerate import diagnostics_constraints

    for candidate in (poses_file.with_name(poses_file.stem + "_diagnostics.csv"),
                      poses_file.with_name("diagnostics.csv")):
        if candidate.is_file():
            c = diagnostics_constraints(candidate)
            return c.weak if len(c.weak) == n else None
    return None


def _classes(manifest: dict) -> tuple[list[str], np.ndarray | None]:
    """The object classes of a simulated sequence's manifest (its ``object_labels``) and each object's class."""
    labels = manifest.get("object_labels")
    if not isinstance(labels, list) or not labels:
        return [], None
    names = list(dict.fromkeys(str(x) for x in labels))
    return names, np.array([names.index(str(x)) for x in labels], dtype=np.uint8)


def run_config_beside(poses_file: Path):
    """Our odometry's config of a run (``NAME_config.yaml`` or ``config.yaml`` beside its poses), or None."""
    from odometry.config import load_config

    for candidate in (poses_file.with_name(poses_file.stem + "_config.yaml"), poses_file.with_name("config.yaml")):
        if candidate.is_file():
            return load_config(candidate)
    return None


# ---------------------------------------------------------------- encoding
def _differences(values: np.ndarray) -> bytes:
    """int16 values as little-endian int16 differences from the previous one (wrapping)."""
    v = values.astype(np.int32)
    d = np.diff(v, prepend=0).astype(np.int64)
    return (((d + 32768) % 65536) - 32768).astype("<i2").tobytes()


def encode_frame(points: np.ndarray, *parts: np.ndarray | None) -> tuple[str, int]:
    """A frame's blob (see the module notes): base64 of zlib of the planar fields; and its point count.

    points: (n, 3) lidar frame, m (those beyond ``LIMIT_M`` left out). parts: (n,) uint8 arrays (None: absent).
    """
    inside = np.all(np.abs(points) < LIMIT_M, axis=1) & np.all(np.isfinite(points), axis=1)
    q = np.round(points[inside] / QUANTUM_M).astype(np.int16)
    chunks = [_differences(q[:, a]) for a in range(3)]
    chunks += [np.asarray(p)[inside].astype(np.uint8).tobytes() for p in parts if p is not None]
    return base64.b64encode(zlib.compress(b"".join(chunks), 6)).decode("ascii"), int(inside.sum())


def _nan_list(a: np.ndarray) -> list:
    """Numbers for JSON with NaN as null, rounded to 6 decimals."""
    return [None if not np.isfinite(x) else round(float(x), 6) for x in np.ravel(a)]


def position_errors(truth: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """(N,) position error of each frame, m (NaN after a divergence)."""
    return np.linalg.norm(poses[:, :3, 3] - truth[:, :3, 3], axis=1)


def page_json(data: PageData) -> dict:
    """The page's data: what ``view_html.js`` reads."""
    n = len(data.points)
    intensity_scale = 1.0
    if data.intensity is not None:
        top = max((float(np.nanmax(x)) if len(x) else 0.0) for x in data.intensity)
        intensity_scale = 255.0 / top if top > 0 else 1.0
    kept_tracks = [i for i, t in enumerate(data.tracks) if t.kept is not None][:8]
    frames, counts = [], []
    for k in range(n):
        kept = None
        if kept_tracks:
            kept = np.zeros(len(data.points[k]), dtype=np.uint8)
            for bit, i in enumerate(kept_tracks):
                kept |= data.tracks[i].kept[k].astype(np.uint8) << bit
        blob, count = encode_frame(
            data.points[k],
            None if data.ring is None else np.clip(data.ring[k], 0, 255),
            None if data.intensity is None else np.clip(np.asarray(data.intensity[k]) * intensity_scale, 0, 255),
            None if data.object_class is None else data.object_class[k],
            None if data.moving is None else data.moving[k],
            kept)
        frames.append(blob)
        counts.append(count)
    from odometry.metrics import trajectory_distances

    reference = data.truth if data.truth is not None else (data.tracks[0].poses if data.tracks else None)
    dist = trajectory_distances(reference) if reference is not None else np.arange(n, dtype=float)
    tracks = []
    for i, t in enumerate(data.tracks):
        tracks.append({"label": t.label, "colour": t.colour, "poses": _nan_list(t.poses),
                       "error": None if data.truth is None else _nan_list(position_errors(data.truth, t.poses)),
                       "weak": None if t.weak is None else [int(x) for x in t.weak],
                       "kept_bit": kept_tracks.index(i) if i in kept_tracks else -1})
    from tools.view import LABEL_COLOURS

    return {
        "title": data.title, "notes": data.notes, "quantum": QUANTUM_M, "rings": data.rings,
        "frames": n, "frame_numbers": [int(x) for x in (data.frame_numbers if data.frame_numbers is not None
                                                        else range(n))],
        "times": _nan_list(data.times), "distance": _nan_list(dist), "counts": counts,
        "fields": {"ring": data.ring is not None, "intensity": data.intensity is not None,
                   "class": data.object_class is not None, "moving": data.moving is not None,
                   "kept": bool(kept_tracks)},
        "classes": data.classes,
        "class_colours": ["#{:02x}{:02x}{:02x}".format(*LABEL_COLOURS.get(c, (180, 180, 180)))
                          for c in data.classes],
        "truth": None if data.truth is None else {"colour": TRUTH_COLOUR, "poses": _nan_list(data.truth),
                                                   "weak": None if data.truth_weak is None else
                                                   [int(x) for x in data.truth_weak]},
        "tracks": tracks, "blobs": frames,
    }


PAGE = """<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{title}</title>
<meta name="viewport" content="width=device-width, initial-scale=1">
<style>
body {{ margin: 0; font: 13px system-ui, sans-serif; color: #222; background: #fafafa; }}
header {{ padding: 6px 10px; }} header h1 {{ font-size: 15px; margin: 0 0 2px; }}
#controls {{ display: flex; flex-wrap: wrap; gap: 4px 12px; align-items: center; padding: 4px 10px; }}
#controls label {{ white-space: nowrap; }} #frame {{ width: 320px; }}
#stage {{ position: relative; height: 62vh; min-height: 320px; background: #fff; border-top: 1px solid #ddd;
  border-bottom: 1px solid #ddd; }}
#view {{ width: 100%; height: 100%; display: block; cursor: grab; }}
.caption {{ position: absolute; top: 4px; padding: 1px 6px; background: rgba(255,255,255,.85); font-size: 12px; }}
#legend {{ padding: 4px 10px; }} #legend span {{ margin-right: 12px; white-space: nowrap; }}
.swatch {{ display: inline-block; width: 10px; height: 10px; margin-right: 4px; vertical-align: -1px; }}
#plot {{ width: 100%; height: 150px; display: block; cursor: pointer; }}
#readout {{ padding: 2px 10px; font-variant-numeric: tabular-nums; }}
#errors {{ color: #b00; padding: 0 10px; white-space: pre-wrap; }}
</style></head>
<body data-status="loading">
<header><h1>{title}</h1><div id="notes"></div></header>
<div id="controls">
 <button id="play" title="play / pause (space)">&#9654;</button>
 <label>frame <input id="frame" type="range" min="0" value="0" step="1"> <span id="frame-label"></span></label>
 <label>colour <select id="colour"></select></label>
 <label>scans placed by <select id="place"></select></label>
 <label><input id="split" type="checkbox"> side by side, right by <select id="place2"></select></label>
 <label>trail <input id="trail" type="number" min="0" max="50" value="2" style="width:3.5em"> scans</label>
 <label>point <input id="size" type="range" min="1" max="6" step="0.5" value="2"></label>
 <label><input id="follow" type="checkbox" checked> follow</label>
 <button id="top">top view</button>
</div>
<div id="stage"><canvas id="view"></canvas><div id="cap-left" class="caption"></div>
<div id="cap-right" class="caption"></div></div>
<div id="legend"></div>
<div id="readout"></div>
<canvas id="plot"></canvas>
<div id="errors"></div>
<script id="salo-data" type="application/json">{data}</script>
<script>{script}</script>
</body></html>
"""


def write_page(data: PageData, path: str | Path) -> Path:
    """Write ``data`` as one self-contained HTML page (atomically); the path."""
    import html

    payload = json.dumps(page_json(data), separators=(",", ":"), allow_nan=False).replace("</", "<\\/")
    text = PAGE.format(title=html.escape(data.title), data=payload, script=ASSETS.read_text())
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, text)
    return path




# ---------------------------------------------------------------- a bench's pages
def bench_pages(out: str | Path, sequence_ids: list[str] | None = None, *, max_points: int | None = None,
                on_page=None) -> dict[str, Path]:
    """A page per sequence of a ``salo bench`` output folder (``OUT/views/SEQUENCE.html``) with every method
    that ran on it without failing; {sequence id: page}.

    sequence_ids: only these (default: every sequence with a result). on_page(id) before each.
    Raises PageError when the folder holds no bench result.
    """
    from tools.leaderboard.results import read_result

    out = Path(out)
    root = out / "results"
    if not root.is_dir():
        raise PageError(f"{out}: not a salo bench output folder (no results/)")
    by_sequence: dict[str, list[tuple[dict, Path]]] = {}
    for folder in sorted(p for p in root.glob("*/*") if p.is_dir()):
        r = read_result(folder)
        if r is None or r.get("status") != "ok" or not (folder / "poses.txt").is_file():
            continue
        by_sequence.setdefault(r["sequence"], []).append((r, folder))
    pages = {}
    for seq_id in sequence_ids if sequence_ids is not None else sorted(by_sequence):
        found = by_sequence.get(seq_id, [])
        path = Path(found[0][0]["sequence_path"]) if found else out / "sequences" / seq_id
        if not path.is_dir():
            continue
        if on_page is not None:
            on_page(seq_id)
        runs = {r["label"]: folder / "poses.txt" for r, folder in found}
        configs = {r["label"]: run_config_beside(folder / "poses.txt") for r, folder in found}
        data = sequence_page(path, runs, max_points=max_points, configs=configs,
                             title=f"{seq_id}: " + (", ".join(runs) if runs else "no run"))
        pages[seq_id] = write_page(data, out / "views" / f"{seq_id}.html")
    return pages


__all__ = ["LIMIT_M", "QUANTUM_M", "PageData", "PageError", "Track", "bench_pages", "encode_frame", "kept_by_filters",
           "page_json", "position_errors", "read_poses_file", "run_config_beside", "sequence_page", "write_page"]
