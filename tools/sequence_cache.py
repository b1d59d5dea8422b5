"""The simulated sequences experiments run on, simulated once and cached by their parameters.

A ``SequenceSpec`` names everything that determines a simulated sequence: the
scene and its seed (which also seeds the sensor noise, as ``salo simulate
--scene --seed`` does), scene parameter overrides, the sensor, its range
noise, the number of frames and the start time along the scene's path.
``ensure_sequence`` returns the sequence folder for a spec, simulating it into
the cache folder only when no complete copy is there. The folder's name ends
in a key: a hash of the spec, the resolved sensor description, the scene
mesh's sha256 and the package version, so a change to any of them (a scene
generator edited, a preset changed) simulates afresh instead of reusing a
stale copy. The sequence's manifest records the spec and the key.

``load_sequence`` is what the experiments call: with no cache folder it
simulates the spec straight into memory (``simlidar.in_memory``; nothing is
written, a 300-frame salo32 sequence takes about 800 MB while it is used),
with one it goes through ``ensure_sequence`` and reads the folder back.

The cache is capped: after each use, the least recently used sequences
(a folder's modification time is touched on every use) are removed until the
cache holds at most ``cache_limit_bytes`` (default 20 GB, ``--cache-limit-gb``),
never the one just used; each removal is logged as a warning (which the
command line prints). A salo32 frame takes about 4.4 MB on disk (points plus
the compact truth): a 300-frame sequence is about 1.3 GB.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import shutil
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

# The paper's sensor, its stated noise class (2 cm, 1 sigma).
DEFAULT_SENSOR = "salo32"
DEFAULT_NOISE_STD_M = 0.02
# The cache's default size cap: the table's six 300-frame salo32 sequences (8 GB) and the studies' fit.
DEFAULT_CACHE_LIMIT_BYTES = 20 * 10**9


@dataclass(frozen=True)
class SequenceSpec:
    """Everything that determines one simulated sequence.

    scene: a ``scenes`` name (city, tunnel, highway, open, forest).
    seed: the scene's seed and the simulator's noise seed.
    frames: sweeps to simulate (10 Hz for the presets: 300 frames = 30 s).
    sensor: preset name or YAML path. noise_std_m: range noise, 1 sigma, m
        (overrides the sensor's). start_s: time along the path of the first sweep, s.
    overrides: scene parameter overrides as sorted (name, value) pairs.
    label: display name (default ``scene-seed``).
    """

    scene: str
    seed: int = 0
    frames: int = 300
    sensor: str = DEFAULT_SENSOR
    noise_std_m: float = DEFAULT_NOISE_STD_M
    start_s: float = 0.0
    overrides: tuple[tuple[str, Any], ...] = ()
    label: str | None = None

    def __post_init__(self) -> None:
        if self.frames < 2:
            raise ValueError(f"sequence {self.name}: frames must be >= 2, got {self.frames}")
        if not self.noise_std_m >= 0:
            raise ValueError(f"sequence {self.name}: noise_std_m must be >= 0, got {self.noise_std_m}")
        object.__setattr__(self, "overrides", tuple(sorted((str(k), v) for k, v in self.overrides)))

    @property
    def name(self) -> str:
        return self.label or f"{self.scene}-{self.seed}"

    def to_dict(self) -> dict:
        d = asdict(self)
        d["overrides"] = dict(self.overrides)
        d["name"] = self.name
        return d

    def with_changes(self, **changes) -> SequenceSpec:
        return SequenceSpec(**{**asdict(self), **changes})


def parse_spec(text: str, **defaults) -> SequenceSpec:
    """``scene[:seed[:frames]]`` (e.g. ``city:2:300``) -> a spec with ``defaults`` for the rest."""
    parts = text.split(":")
    if not parts[0] or len(parts) > 3:
        raise ValueError(f"sequence {text!r}: expected SCENE[:SEED[:FRAMES]], e.g. city:2:300")
    kwargs = dict(defaults)
    try:
        if len(parts) > 1 and parts[1]:
            kwargs["seed"] = int(parts[1])
        if len(parts) > 2 and parts[2]:
            kwargs["frames"] = int(parts[2])
    except ValueError:
        raise ValueError(f"sequence {text!r}: seed and frames must be whole numbers") from None
    return SequenceSpec(scene=parts[0], **kwargs)


def table_suite(frames: int = 300, sensor: str = DEFAULT_SENSOR, noise_std_m: float = DEFAULT_NOISE_STD_M):
    """The default suite of the table: three city seeds, a tunnel, a highway, open ground.

    300 frames (30 s) from a standing start cover about 250 m in the city, 400 m
    in the tunnel (80 m approach, then inside), 650 m on the highway and 220 m on
    open ground: every sequence holds 100 m segments.
    """
    common = {"frames": frames, "sensor": sensor, "noise_std_m": noise_std_m}
    return [
        SequenceSpec("city", 1, **common),
        SequenceSpec("city", 2, **common),
        SequenceSpec("city", 3, **common),
        SequenceSpec("tunnel", 1, **common),
        SequenceSpec("highway", 1, **common),
        SequenceSpec("open", 1, **common),
    ]


def _sensor_model(spec: SequenceSpec):
    from simlidar.sensor import load_sensor

    return load_sensor(spec.sensor).with_overrides(range_noise_std_m=spec.noise_std_m)


def _build(spec: SequenceSpec):
    from tools.worlds import build_scene_world

    return build_scene_world(spec.scene, spec.seed, dict(spec.overrides))


def spec_key(spec: SequenceSpec, mesh_sha256: str) -> str:
    """10 hex digits identifying the simulated content of ``spec`` (see the module notes)."""
    from tools.records import package_version

    content = {k: v for k, v in spec.to_dict().items() if k not in ("label", "name")}
    content.update(sensor_model=_sensor_model(spec).to_dict(), mesh_sha256=mesh_sha256, version=package_version())
    return hashlib.sha256(json.dumps(content, sort_keys=True, default=str).encode()).hexdigest()[:10]


def _complete(folder: Path, frames: int) -> bool:
    from simlidar.dataset import open_sequence
    from simlidar.sequence import DatasetError

    if not (folder / "manifest.json").is_file():
        return False
    try:
        return len(open_sequence(folder)) == frames
    except DatasetError:
        return False


def ensure_sequence(spec: SequenceSpec, cache_dir: str | Path, progress: bool = False,
                    cache_limit_bytes: int | None = DEFAULT_CACHE_LIMIT_BYTES) -> Path:
    """The folder of ``spec``'s sequence under ``cache_dir``, simulated there if not yet cached.

    Marks it used and then trims the cache to ``cache_limit_bytes`` (``trim_cache``; None: no cap).
    Raises ValueError when the scene's path is too short for the frames asked.
    """
    from tqdm import tqdm

    from tools.runners import PathTooShort, simulate_scene

    scene = _build(spec)
    key = spec_key(spec, scene.info["mesh_sha256"])
    folder = Path(cache_dir) / f"{spec.name}-{key}"
    if _complete(folder, spec.frames):
        log.info("sequence %s: cached in %s", spec.name, folder)
    else:
        log.info("sequence %s: simulating %d frames into %s", spec.name, spec.frames, folder)
        with tqdm(total=spec.frames, unit="sweep", desc=f"simulate {spec.name}", disable=not progress,
                  dynamic_ncols=True) as bar:
            try:
                simulate_scene(scene, _sensor_model(spec), folder, spec.frames, seed=spec.seed, start_s=spec.start_s,
                               force=True, on_frame=lambda k, scan: bar.update(1),
                               info={"command": "experiment suite", "suite_spec": spec.to_dict(), "suite_key": key})
            except PathTooShort as exc:
                raise _too_short(spec, exc) from None
    os.utime(folder)  # used now: the last to be evicted
    if cache_limit_bytes is not None:
        trim_cache(cache_dir, cache_limit_bytes, keep=folder)
    return folder


def _too_short(spec: SequenceSpec, exc) -> ValueError:
    return ValueError(f"sequence {spec.name}: the {spec.scene} path lasts {exc.duration_s:.1f} s, room for "
                      f"{exc.available} sweeps after {exc.start_s:g} s, not {exc.frames}")


def _folder_bytes(folder: Path) -> int:
    return sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())


def trim_cache(cache_dir: str | Path, limit_bytes: int, keep: Path | None = None) -> list[Path]:
    """Remove the least recently used sequences of ``cache_dir`` until it holds at most ``limit_bytes``.

    Only complete sequence folders (a ``manifest.json``) count and go, oldest
    modification time first, never ``keep``; each removal is logged as a
    warning with its size and last use. Returns the removed folders.
    """
    from datetime import datetime

    root = Path(cache_dir)
    if not root.is_dir():
        return []
    entries = [(f.stat().st_mtime, f, _folder_bytes(f)) for f in root.iterdir()
               if f.is_dir() and (f / "manifest.json").is_file()]
    total = sum(size for _, _, size in entries)
    removed = []
    for mtime, folder, size in sorted(entries, key=lambda e: e[0]):
        if total <= limit_bytes:
            break
        if keep is not None and folder.resolve() == Path(keep).resolve():
            continue
        shutil.rmtree(folder, ignore_errors=True)
        total -= size
        removed.append(folder)
        log.warning("sequence cache %s over its %.3g GB cap: removed %s (%.3g GB, last used %s)", root,
                    limit_bytes / 1e9, folder.name, size / 1e9,
                    datetime.fromtimestamp(mtime).isoformat(timespec="seconds"))
    return removed


def load_sequence(spec: SequenceSpec, cache_dir: str | Path | None = None, progress: bool = False,
                  fields: str = "simulated", cache_limit_bytes: int | None = DEFAULT_CACHE_LIMIT_BYTES):
    """``spec``'s sequence to run on: in memory (``cache_dir`` None: nothing written) or cached on disk.

    fields: what the in-memory frames carry (``simlidar.in_memory``: "simulated", or "truth" for
    studies that need the per-point truth); a folder always has it all. Raises ValueError when the
    scene's path is too short for the frames asked.
    """
    from simlidar.dataset import open_sequence

    if cache_dir is not None:
        return open_sequence(ensure_sequence(spec, cache_dir, progress, cache_limit_bytes))
    from tqdm import tqdm

    from simlidar.in_memory import simulate_in_memory
    from tools.runners import PathTooShort

    scene = _build(spec)
    sensor = _sensor_model(spec)
    available = scene.sweeps_available(sensor, spec.start_s)
    if spec.frames > available:
        raise _too_short(spec, PathTooShort(spec.scene, float(scene.trajectory.duration_s), available, spec.start_s,
                                            spec.frames))
    log.info("sequence %s: simulating %d frames in memory", spec.name, spec.frames)
    with tqdm(total=spec.frames, unit="sweep", desc=f"simulate {spec.name}", disable=not progress,
              dynamic_ncols=True) as bar:
        return simulate_in_memory(scene.world, scene.trajectory, sensor, spec.frames, seed=spec.seed,
                                  t_start=spec.start_s, fields=fields, name=spec.name,
                                  on_frame=lambda k: bar.update(1),
                                  info={"suite_spec": spec.to_dict(), **scene.info,
                                        "noise_std_m": sensor.range_noise_std_m})
