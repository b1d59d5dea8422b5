"""The named stress scenes of moving traffic, each with its static twin: what ``salo bench --suite stress`` runs.

Four scripted scenes (``scenes.red_light``, ``scenes.traffic_jam``, ``scenes.overtaking_lorry``,
``scenes.lead_vehicle``; docs/traffic.md), each simulated twice with the same seed: with its
moving objects, and as its static twin (parameter ``moving`` false: the same world and the
same ego motion, nothing else moving), so what the traffic costs a method is the
difference between the two. Their figures beyond the suite's (``tools.family_suite.trajectory_figures``):
the end's position error and the motion a method invents while the sensor truly stands
still (the red light's wait, the jam's stops).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

STRESS_SENSOR = "salo32"
STRESS_NOISE_M = 0.02


@dataclass(frozen=True)
class StressSequence:
    """One sequence: a stress scene, with its moving objects or as its static twin, its frames and start (s)."""

    scene: str
    moving: bool
    frames: int
    start_s: float
    seed: int = 0
    sensor: str = STRESS_SENSOR
    noise_std_m: float = STRESS_NOISE_M

    @property
    def name(self) -> str:
        return f"{self.scene}-{'moving' if self.moving else 'static'}"


# Each scene's window: the red light's approach, wait and departure; the jam's stops and creeps; the lorry
# from behind to ahead; the van's steady drive.
STRESS = (
    StressSequence("red_light", True, 300, 6.0),
    StressSequence("traffic_jam", True, 300, 0.0),
    StressSequence("overtaking_lorry", True, 250, 0.0),
    StressSequence("lead_vehicle", True, 250, 0.0),
)


def stress_suite(scenes: tuple[str, ...] = (), frames: int | None = None) -> list[StressSequence]:
    """Every stress scene (or those named), with its moving objects then as its static twin."""
    known = [s.scene for s in STRESS]
    unknown = [s for s in scenes if s not in known]
    if unknown:
        raise ValueError(f"unknown stress scene {unknown[0]!r} (known: {', '.join(known)})")
    chosen = [s for s in STRESS if not scenes or s.scene in scenes]
    if frames is not None:
        chosen = [replace(s, frames=frames) for s in chosen]
    return [replace(s, moving=m) for s in chosen for m in (True, False)]


def simulate_to_folder(seq: StressSequence, out, force: bool = False):
    """A stress sequence as a sequence folder (``tools.runners.simulate_scene``). Returns the path."""
    from simlidar.sensor import load_sensor
    from tools.runners import simulate_scene
    from tools.worlds import build_scene_world

    scene = build_scene_world(seq.scene, seq.seed, {"moving": seq.moving})
    sensor = load_sensor(seq.sensor).with_overrides(range_noise_std_m=seq.noise_std_m)
    done = simulate_scene(scene, sensor, out, seq.frames, seed=seq.seed, start_s=seq.start_s, force=force,
                          info={"command": "bench", "stress_sequence": asdict(seq)})
    return done.path


__all__ = ["STRESS", "StressSequence", "simulate_to_folder", "stress_suite"]
