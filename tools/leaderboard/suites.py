"""The sequences a bench runs over: the regression suite, the generalisation suite, its weather and traffic suites,
the stress scenes, or a sweep spec.

Each becomes a list of ``BenchSequence``: a simulated sequence folder under the
bench's output folder (simulated once, reused by every later run), its scene
family (the leaderboard's table groups by it), and the per-point fields its
methods may see (the generalisation suite's "real" kind: none, as real KITTI).
The weather suite's sequences are grouped by their weather condition (a table
each: clear air, light fog, dense fog, rain, snow), the clear one the others' twin; the
traffic suite's by family, with traffic and static; the stress suite's by scene, moving
and its static twin.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

SUITES = ("regress", "generalize", "weather", "traffic", "stress")


class SuiteError(ValueError):
    """A suite cannot be read or a sequence of it simulated; the message says which."""


@dataclass(frozen=True)
class BenchSequence:
    """One sequence of a bench.

    id: a folder-safe name, unique in the suite. family: the scene family (table group).
    path: the simulated sequence folder. fields: per-point fields its methods may see
    (None: the bench's own choice).
    """

    id: str
    family: str
    path: Path
    fields: tuple[str, ...] | None = None

    @property
    def key(self) -> str:
        """A hash of the sequence's manifest: a result is for this very sequence."""
        return hashlib.sha256((self.path / "manifest.json").read_bytes()).hexdigest()[:16]


def bench_sequences(suite: str | Path, out: str | Path, *, frames: int | None = None,
                    families: tuple[str, ...] = (), on_sequence: Callable[[str], None] | None = None
                    ) -> list[BenchSequence]:
    """The suite's sequences under ``out``/sequences, simulating those not there yet.

    suite: "regress" (``tools.sweep.regress.SUITE``), "generalize" (the evaluation split of
    ``tools.family_suite``; ``frames`` and ``families`` narrow it), "weather" (its simulated
    sequences in each weather condition, ``family_suite.weather_suite``; the same narrowing), "traffic"
    (its simulated sequences of the families with traffic, each with moving traffic and as its static
    twin, ``family_suite.traffic_suite``; the same narrowing), "stress" (the named stress scenes and
    their static twins, ``tools.stress_suite``; ``families`` names scenes) or a sweep spec YAML (its
    scenes x seeds x sensors x noise levels; its variants are not used).
    on_sequence(id) before each simulation. Raises SuiteError.
    """
    out = Path(out)
    if str(suite) in ("generalize", "weather", "traffic"):
        return _generalize(out, frames, families, on_sequence, weather=str(suite) == "weather",
                           traffic=str(suite) == "traffic")
    if str(suite) == "stress":
        return _stress(out, frames, families, on_sequence)
    if families:
        raise SuiteError("--families narrows the generalize, weather, traffic and stress suites only")
    return _sweep(suite, out, frames, on_sequence)


def _sweep(suite, out: Path, frames: int | None, on_sequence) -> list[BenchSequence]:
    from dataclasses import replace

    from tools.sweep import SpecError, Store, load_spec
    from tools.sweep.regress import suite_spec
    from tools.sweep.tasks import SimJob, simulate_task

    try:
        spec = suite_spec() if str(suite) == "regress" else load_spec(suite)
    except SpecError as exc:
        raise SuiteError(str(exc)) from None
    if frames is not None:
        spec = replace(spec, frames=frames)
    store = Store(out.resolve())
    sims = {}
    for run in spec.runs():
        sims.setdefault(run.sim_key, run.sim)
    sequences = []
    for key, sim in sims.items():
        name = f"{sim.scene}-seed{sim.seed}-{Path(sim.sensor).stem}-noise{sim.noise_std_m:g}"
        if not store.sequence_ready(key):
            if on_sequence is not None:
                on_sequence(name)
            done = simulate_task(SimJob(str(store.root), key, sim.scene, sim.seed, sim.scene_overrides,
                                        sim.sensor_model, sim.frames, sim.start_s, sim.motion_distortion))
            if not done["ok"]:
                raise SuiteError(f"{name}: {done['error']}")
        sequences.append(BenchSequence(name, sim.scene, store.sequence_dir(key), spec.fields))
    return sequences


def _generalize(out: Path, frames: int | None, families: tuple[str, ...], on_sequence,
                weather: bool = False, traffic: bool = False) -> list[BenchSequence]:
    from tools.family_suite import (
        DEFAULT_FRAMES,
        EVALUATION_SEEDS,
        simulate_to_folder,
        suite,
        traffic_suite,
        weather_suite,
    )

    try:
        chosen = (weather_suite if weather else traffic_suite if traffic else suite)
        seqs = chosen(EVALUATION_SEEDS, frames or DEFAULT_FRAMES, tuple(families) or None)
    except ValueError as exc:
        raise SuiteError(str(exc)) from None
    sequences = []
    for seq in seqs:
        path = _simulated_once(seq, out, simulate_to_folder, on_sequence)
        fields = None if seq.kind == "simulated" else ()
        group = seq.weather if seq.weather is not None else f"{seq.family} ({'traffic' if seq.traffic else 'static'})" \
            if traffic else f"{seq.family} ({seq.kind})"
        sequences.append(BenchSequence(seq.name, group, path, fields))
    return sequences


def _stress(out: Path, frames: int | None, scenes: tuple[str, ...], on_sequence) -> list[BenchSequence]:
    """The stress scenes and their static twins, a table each (``tools.stress_suite``)."""
    from tools.stress_suite import simulate_to_folder, stress_suite

    try:
        seqs = stress_suite(tuple(scenes), frames)
    except ValueError as exc:
        raise SuiteError(str(exc)) from None
    sequences = []
    for seq in seqs:
        path = _simulated_once(seq, out, simulate_to_folder, on_sequence)
        sequences.append(BenchSequence(seq.name, f"{seq.scene} ({'moving' if seq.moving else 'static twin'})",
                                       path, None))
    return sequences


def _simulated_once(seq, out: Path, simulate_to_folder, on_sequence) -> Path:
    """``OUT/sequences/<name>`` of a suite's sequence, simulated by ``simulate_to_folder(seq, path, force=True)``
    unless a complete one is there (its manifest is written last); SuiteError naming it when it fails."""
    path = out / "sequences" / seq.name
    if not (path / "manifest.json").is_file():
        if on_sequence is not None:
            on_sequence(seq.name)
        try:
            simulate_to_folder(seq, path, force=True)
        except ValueError as exc:
            raise SuiteError(f"{seq.name}: {exc}") from None
    return path


__all__ = ["SUITES", "BenchSequence", "SuiteError", "bench_sequences"]
