"""Benchmark of the simulator: sweep speed against the bare Embree call, writing to disk, and memory.

    python -m tools.bench_sim                 # sweep speed, salo32, >= 100k-triangle world, and
                                              # end to end: salo simulate --scene city --seed 3 --frames 100
    python -m tools.bench_sim --e2e-frames 0  # skip the end-to-end run
    python -m tools.bench_sim --imu           # the end-to-end run again with the sensor's IMU on (200 Hz):
                                              # its cost against the run with it off, same process
    python -m tools.bench_sim --memory 1000   # also a 1000-frame sequence: peak RSS stays flat
    python -m tools.bench_sim --big-world 2000000 --e2e-frames 0   # a tiled city of >= 2M triangles:
                                              # load time, sweeps/s, memory over a 300-frame sequence
    python -m tools.bench_sim --weather-repeats 0  # skip the weather's cost (simlidar.weather)
    python -m tools.bench_sim --actors-repeats 0   # skip the moving actors' cost (simlidar.actors)

The end-to-end run calls ``tools.runners.simulate_scene``, the function behind
``salo simulate --scene``, writing the sequence (scans and truth) to a temporary
folder, and casts the same sequence's rays (each column from its own firing
pose) with the bare 2-thread Embree call in the same run: sweeps/s of both, the
ratio, and bytes on disk per return.

The weather's cost: CPU time per sweep of the same sweeps (the end-to-end city's
sensor and path, interleaved so that other jobs on the machine weigh on each alike)
with the sensor as it is, with the receiver's power model on in clear air, and in
dense fog, rain and snow, each against the sensor as it is.

The moving actors' cost: CPU time per sweep with 20 and with 100 actors near the sensor
(the city's traffic at high densities, the nearest ones), interleaved with the static world's.

Prints figures; it asserts nothing (speed is measured here, never in tests).
"""

from __future__ import annotations

import argparse
import resource
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
import trimesh

from simlidar.sensor import load_sensor
from simlidar.simulate import simulate_sequence
from simlidar.sweep import SweepSimulator
from simlidar.trajectory import SampledTrajectory
from simlidar.world import World


def bench_world(seed: int = 0) -> World:
    """A deterministic street-like world of >= 100k triangles: terrain, blocks, round objects."""
    rng = np.random.default_rng(seed)
    n = 160
    xs = np.linspace(-300, 300, n)
    gx, gy = np.meshgrid(xs, xs)
    gz = 0.3 * np.sin(gx / 37.0) * np.cos(gy / 53.0)
    verts = [np.c_[gx.ravel(), gy.ravel(), gz.ravel()]]
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1))
    a = (j * n + i).ravel()
    faces = [np.r_[np.c_[a, a + 1, a + n + 1], np.c_[a, a + n + 1, a + n]]]
    ids = [np.zeros(len(faces[0]), dtype=int)]
    labels = ["ground"]
    base = len(verts[0])
    parts = []
    for _ in range(300):  # buildings along both sides of streets every 60 m
        x, y = rng.uniform(-250, 250, 2)
        if min(abs(x) % 60, abs(y) % 60) < 12:
            continue
        b = trimesh.creation.box((rng.uniform(8, 25), rng.uniform(8, 25), rng.uniform(6, 30)))
        b.apply_translation((x, y, b.extents[2] / 2))
        parts.append((b, "building"))
    for _ in range(50):  # trees / poles as tessellated spheres
        s = trimesh.creation.icosphere(subdivisions=3, radius=rng.uniform(1, 3))
        s.apply_translation((rng.uniform(-250, 250), rng.uniform(-250, 250), 4))
        parts.append((s, "vegetation"))
    for k, (m, label) in enumerate(parts, start=1):
        verts.append(m.vertices)
        faces.append(m.faces + base)
        ids.append(np.full(len(m.faces), k))
        labels.append(label)
        base += len(m.vertices)
    return World(np.vstack(verts), np.vstack(faces), np.concatenate(ids), labels, "bench world")


def straight_path(speed: float = 10.0, duration: float = 200.0) -> SampledTrajectory:
    t = np.linspace(0, duration, 2001)
    T = np.tile(np.eye(4), (len(t), 1, 1))
    # along the street y = 0 (kept free of buildings), back and forth within the world
    x = -240 + (speed * t) % 480
    T[:, 0, 3], T[:, 2, 3] = x, 1.9 + 0.3 * np.sin(x / 37.0)
    return SampledTrajectory(t, T)


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def bench_sweep(world: World, sensor_name: str, repeats: int) -> None:
    sensor = load_sensor(sensor_name)
    traj = straight_path()
    sim = SweepSimulator(world, sensor, seed=0)
    rc = sim.raycaster
    sim.sweep(traj, 0.0)  # warm up
    t = time.perf_counter()
    returns = 0
    for k in range(repeats):
        returns += len(sim.sweep(traj, 0.1 * k, frame_index=k))
    t_sweep = (time.perf_counter() - t) / repeats

    # the same rays handed to Embree directly (no pose, noise, normal or packing work)
    T = traj.pose_at(np.array([0.0]))[0]
    o32 = np.ascontiguousarray(np.broadcast_to(T[:3, 3] - rc.offset, (sensor.rays_per_sweep, 3)), np.float32)
    d32 = np.ascontiguousarray(sim._dir_local @ T[:3, :3].T, np.float32)
    dist = np.full(sensor.rays_per_sweep, sensor.max_range_m + 1.0, np.float32)
    t = time.perf_counter()
    for _ in range(repeats):
        rc._scene.run(o32, d32, dists=dist.copy(), output=1)  # (embreex writes the hits back into dists)
    t_bare1 = (time.perf_counter() - t) / repeats
    t = time.perf_counter()
    for _ in range(repeats):
        rc.cast_raw(o32, d32, dist)
    t_bare = (time.perf_counter() - t) / repeats
    rays = sensor.rays_per_sweep
    print(f"sensor {sensor.name}: {rays} rays per sweep, {returns / repeats:.0f} returns per sweep")
    for what, t_ in (
        ("full sweep (motion, noise, normals)", t_sweep),
        (f"bare embreex, {rc.threads} threads", t_bare),
        ("bare embreex, 1 thread", t_bare1),
    ):
        print(f"  {what:36s} {1 / t_:6.1f} sweeps/s  {rays / t_ / 1e6:5.2f} M rays/s")
    print(f"  sweep time / bare cast ({rc.threads} threads): {t_sweep / t_bare:.2f}x")
    print(f"  sweep time / bare cast (1 thread):  {t_sweep / t_bare1:.2f}x")


def bench_end_to_end(scene_name: str, seed: int, sensor_name: str, frames: int, tmp_root: str | None,
                     imu: bool = False, rounds: int = 5) -> None:
    """``salo simulate --scene NAME --seed S --frames F`` through its library function, against the bare cast.

    The whole call once (BVH, inside check, sweeps, writing); then, for the CPU per sweep, ``rounds`` rounds
    of the same sequence simulated again with the world's BVH built (``simulate_sequence``, writing
    included), the bare cast of its rays and the floor's files and noise, one after the other in each round,
    so that other jobs on the machine weigh on each alike. ``imu``: then again with the sensor's IMU on,
    against the first run.
    """
    from tools.runners import simulate_scene
    from tools.worlds import build_scene_world

    sensor = load_sensor(sensor_name)
    scene = build_scene_world(scene_name, seed, {})
    warm_up(scene.world, sensor)
    marks: dict[int, float] = {}

    def on_frame(k, scan):
        marks.setdefault(k, time.perf_counter())

    with tempfile.TemporaryDirectory(dir=tmp_root) as tmp:
        out = Path(tmp) / "seq"
        t0, c0 = time.perf_counter(), time.process_time()
        done = simulate_scene(scene, sensor, out, frames, seed=seed, on_frame=on_frame)
        t_end, cpu_sim = time.perf_counter(), time.process_time() - c0  # the whole call, for the IMU's ratio
        sizes = {sub: sum(p.stat().st_size for p in (out / sub).iterdir()) for sub in ("velodyne", "sidecar")}
        import json

        returns = json.loads((out / "manifest.json").read_text())["points"]
        sim = SweepSimulator(scene.world, sensor, seed=seed)
        rays = frame_rays(sim, scene.trajectory, np.arange(frames) * sensor.sweep_period_s)
        cpu = {"simulate": 0.0, "bare cast": 0.0, "files": 0.0, "noise": 0.0}
        for r in range(rounds):
            c = time.process_time()
            simulate_sequence(scene.world, scene.trajectory, sensor, Path(tmp) / f"again{r}", frames=frames, seed=seed,
                              simulator=sim)
            cpu["simulate"] += time.process_time() - c
            shutil.rmtree(Path(tmp) / f"again{r}")  # (a new folder each round, removed outside the timing)
            cpu["bare cast"] += bare_cast_cpu_s(sim.raycaster, rays, sensor) * frames
            cpu["files"] += floor_write_cpu_s(Path(tmp) / f"floor{r}", frames, sizes) * frames
            shutil.rmtree(Path(tmp) / f"floor{r}")
            cpu["noise"] += floor_noise_cpu_s(returns // frames) * frames
        per = {k: v / (rounds * frames) for k, v in cpu.items()}
    t_bare = bare_cast_wall_s(sim.raycaster, rays[:: max(1, frames // 10)], sensor)
    streaming = (frames - 1) / (t_end - marks[0])  # first sweep done -> folder committed
    total = frames / done.seconds
    per_return = {k: v / returns for k, v in sizes.items()}
    floor = per["bare cast"] + per["files"] + per["noise"]
    print(f"end to end: salo simulate --scene {scene_name} --seed {seed} --frames {frames} --sensor {sensor.name} "
          f"({returns / frames:.0f} returns per sweep)")
    print(f"  bare embreex, {sim.raycaster.threads} threads, same rays      {1 / t_bare:6.1f} sweeps/s")
    print(f"  simulate, truth written (streaming)          {streaming:6.1f} sweeps/s   "
          f"{1 / (streaming * t_bare):.2f}x the bare cast's time")
    print(f"  simulate, whole call (BVH, inside check)     {total:6.1f} sweeps/s   "
          f"({t_end - t0:.1f} s, of which {marks[0] - t0:.1f} s before the first sweep was done)")
    print(f"  CPU time per sweep (all threads; what other jobs on the machine do not change), {rounds} interleaved "
          f"rounds of {frames} sweeps: simulate {1e3 * per['simulate']:.1f} ms (writing included), bare cast "
          f"{1e3 * per['bare cast']:.1f} ms ({per['simulate'] / per['bare cast']:.2f}x)")
    print(f"  on disk per return: scan {per_return['velodyne']:.1f} B + truth {per_return['sidecar']:.1f} B = "
          f"{sum(per_return.values()):.1f} B")
    print(f"  floor beyond the cast, CPU per sweep: the frame's files written new with their sha256 "
          f"{1e3 * per['files']:.1f} ms, its range noise drawn {1e3 * per['noise']:.1f} ms; floor "
          f"{1e3 * floor:.1f} ms ({floor / per['bare cast']:.2f}x the bare cast's time: no truth computed, nothing "
          f"encoded)")
    print(f"  simulate / floor: {per['simulate'] / floor:.2f}x")
    if imu:
        import dataclasses

        with_imu = sensor.with_overrides(imu=dataclasses.replace(sensor.imu, enabled=True))
        with tempfile.TemporaryDirectory(dir=tmp_root) as tmp:
            c_on, t_on = time.process_time(), time.perf_counter()
            simulate_scene(scene, with_imu, Path(tmp) / "seq", frames, seed=seed)
            cpu_imu, wall_imu = time.process_time() - c_on, time.perf_counter() - t_on
            imu_bytes = sum((Path(tmp) / "seq" / f).stat().st_size for f in ("imu.csv", "imu_truth.csv"))
        from simlidar.imu import simulate_imu

        c_on = time.process_time()
        simulate_imu(scene.trajectory, with_imu.imu, 0.0, frames * sensor.sweep_period_s, seed)
        cpu_model = time.process_time() - c_on
        print(f"  with the IMU on ({with_imu.imu.update_rate:g} Hz): CPU per sweep {1e3 * cpu_imu / frames:.0f} ms, "
              f"{cpu_imu / cpu_sim:.3f}x the run with it off (wall {wall_imu / (t_end - t0):.3f}x); the IMU's "
              f"samples alone {1e3 * cpu_model:.0f} ms for the {frames * sensor.sweep_period_s:g} s; "
              f"imu.csv + imu_truth.csv {imu_bytes / 1e6:.2f} MB")


def warm_up(world: World, sensor) -> None:
    """One sweep of a small part of ``world``: the compiled kernels loaded (or compiled) before timing."""
    keep = slice(0, min(len(world.faces), 2000))
    small = World(world.vertices, world.faces[keep], world.face_object_id[keep], world.object_labels, "warm-up")
    traj = SampledTrajectory(np.array([0.0]), np.eye(4)[None])
    for motion in (True, False):
        sim = SweepSimulator(small, sensor, seed=0, motion_distortion=motion, threads=1)
        scan = sim.sweep(traj, 0.0)
    from simlidar.degeneracy import degeneracy
    from simlidar.formats import truth

    truth.encode(np.zeros(len(scan), np.int64), scan.true_range_m, scan.normal, np.zeros(len(scan), np.int64), None, 4)
    degeneracy(scan.true_xyz, scan.normal)


def frame_rays(sim: SweepSimulator, trajectory, starts: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """The rays of sweeps starting at ``starts`` (s), each from its firing pose, float32 in the BVH's frame."""
    rays = []
    for t in starts:
        T = trajectory.pose_at(t + sim._times_unique)
        d = np.einsum("nij,nj->ni", T[sim._ray_time_idx, :3, :3], sim._dir_local)
        o = T[sim._ray_time_idx, :3, 3] - sim.raycaster.offset
        rays.append((np.ascontiguousarray(o, np.float32), np.ascontiguousarray(d, np.float32)))
    return rays


def bare_cast_cpu_s(rc, rays, sensor) -> float:
    """CPU seconds per sweep of the bare threaded Embree call on ``rays`` (no noise, no truth, nothing written)."""
    dist = np.full(sensor.rays_per_sweep, sensor.max_range_m + 1.0, np.float32)
    c = time.process_time()
    for o32, d32 in rays:
        rc.cast_raw(o32, d32, dist)
    return (time.process_time() - c) / len(rays)


def bare_cast_wall_s(rc, rays, sensor, repeats: int = 3) -> float:
    """Wall seconds per sweep of the bare threaded Embree call on ``rays`` (after one warm-up cast)."""
    dist = np.full(sensor.rays_per_sweep, sensor.max_range_m + 1.0, np.float32)
    rc.cast_raw(*rays[0], dist)
    t = time.perf_counter()
    for _ in range(repeats):
        for o32, d32 in rays:
            rc.cast_raw(o32, d32, dist)
    return (time.perf_counter() - t) / (repeats * len(rays))


def bench_actors(scene_name: str, seed: int, sensor_name: str, repeats: int, counts=(20, 100)) -> None:
    """CPU per sweep with ``counts`` moving actors near the sensor against the static world, sweeps interleaved.

    The actors are the scene's traffic at high densities (``scenes.traffic``: vehicles, cyclists, people), the
    ``n`` nearest the sensor in the middle of the swept time, so that all of them are in its range.
    """
    import scenes
    from simlidar.raycast import Raycaster
    from tools.worlds import world_of_scene

    sensor = load_sensor(sensor_name)
    dense = {"enabled": True, "cars_per_km": 150.0, "vans_per_km": 30.0, "lorries_per_km": 15.0, "buses_per_km": 8.0,
             "cyclists_per_km": 40.0, "pedestrians_per_km": 400.0}
    scene = scenes.build_scene(scene_name, seed=seed, traffic=dense)
    t0 = 20.0
    times = t0 + 0.1 * np.arange(repeats)
    ego = scene.trajectory.pose_at(np.array([times.mean()]))[0, :3, 3]
    dist = np.array([np.linalg.norm(a.motion_at(np.array([times.mean()]))[0][0, :3, 3] - ego) for a in scene.actors])
    order = np.argsort(dist)
    world = world_of_scene(scene)
    rc = Raycaster(world.vertices, world.faces)
    sims = {"static": SweepSimulator(world.without_actors(), sensor, seed=seed, raycaster=rc)}
    for n in counts:
        if n > len(order):
            print(f"actors: the scene's dense traffic has {len(order)} actors, not {n}: skipped")
            continue
        chosen = World(world.vertices, world.faces, world.face_object_id, world.object_labels, world.source,
                       actors=[scene.actors[i] for i in order[:n]])
        sims[f"{n} actors"] = SweepSimulator(chosen, sensor, seed=seed, raycaster=rc)
        print(f"  {n} actors: the farthest {dist[order[n - 1]]:.0f} m from the sensor in the middle of the sweeps")
    cpu = dict.fromkeys(sims, 0.0)
    on_actors = dict.fromkeys(sims, 0)
    for sim in sims.values():
        sim.sweep(scene.trajectory, t0 - 1.0)  # warm up (the actors' BVHs, the kernels)
    for k, t in enumerate(times):
        for name, sim in sims.items():
            c = time.process_time()
            scan = sim.sweep(scene.trajectory, float(t), frame_index=k)
            cpu[name] += time.process_time() - c
            on_actors[name] += int(np.sum(scan.object_id >= len(world.object_labels)))
    ref = cpu["static"]
    print(f"actors: {repeats} sweeps each of {sensor_name} in {scene_name} seed {seed} from {t0:g} s, CPU per sweep "
          "(all threads), interleaved")
    for name in sims:
        print(f"  {name:10s} {1e3 * cpu[name] / repeats:6.1f} ms  {cpu[name] / ref:5.2f}x the static sweep   "
              f"({on_actors[name] / repeats:,.0f} returns a sweep off the actors)")


WEATHER_RUNS = {
    "receiver on, clear air": {},
    "dense fog, MOR 60 m": {"fog": {"enabled": True, "mor_m": 60.0}},
    "light fog, MOR 800 m": {"fog": {"enabled": True, "mor_m": 800.0}},
    "rain, 20 mm/h": {"rain": {"enabled": True, "rate_mm_h": 20.0}},
    "snow, 1.5 mm/h": {"snow": {"enabled": True, "rate_mm_h": 1.5}},
}


def bench_weather(scene_name: str, seed: int, sensor_name: str, repeats: int) -> None:
    """CPU per sweep with the receiver and each weather on, against the sensor as it is, sweeps interleaved."""
    from simlidar.raycast import Raycaster
    from simlidar.weather import ReceiverParams, Weather
    from tools.worlds import build_scene_world

    scene = build_scene_world(scene_name, seed, {})
    base = load_sensor(sensor_name)
    rc = Raycaster(scene.world.vertices, scene.world.faces)  # one BVH for all: the same rays cast alike
    sims = {"as it is": SweepSimulator(scene.world, base, seed=seed, raycaster=rc)}
    for name, weather in WEATHER_RUNS.items():
        sensor = base.with_overrides(receiver=ReceiverParams(enabled=True), weather=Weather.from_dict(weather))
        sims[name] = SweepSimulator(scene.world, sensor, seed=seed, raycaster=rc)
    cpu = dict.fromkeys(sims, 0.0)
    returns = dict.fromkeys(sims, 0)
    t0 = 20.0
    for sim in sims.values():
        sim.sweep(scene.trajectory, t0)  # warm up
    for k in range(repeats):
        for name, sim in sims.items():
            c = time.process_time()
            returns[name] += len(sim.sweep(scene.trajectory, t0 + 0.1 * k, frame_index=k))
            cpu[name] += time.process_time() - c
    ref = cpu["as it is"]
    print(f"weather: {repeats} sweeps each of {sensor_name} in {scene_name} seed {seed} from {t0:g} s, CPU per sweep "
          "(all threads), interleaved")
    for name in sims:
        print(f"  {name:24s} {1e3 * cpu[name] / repeats:6.0f} ms  {cpu[name] / ref:5.2f}x the sensor as it is   "
              f"({returns[name] / repeats:,.0f} returns)")


def floor_write_cpu_s(folder: Path, frames: int, sizes: dict[str, int]) -> float:
    """CPU seconds a frame to write a sequence's bytes (``sizes``: bytes per subfolder over ``frames``
    frames) as new files, each in one write with its sha256, by the writer's own
    ``write_checksummed``: the disk work of any simulate, whatever it computes."""
    from simlidar.formats.atomic import write_checksummed

    folder.mkdir()
    blobs = [np.random.default_rng(k).bytes(max(1, n // frames)) for k, n in enumerate(sizes.values())]
    c = time.process_time()
    for k in range(frames):
        for j, blob in enumerate(blobs):
            write_checksummed(folder / f"{k:06d}.{j}", blob)
    return (time.process_time() - c) / frames


def floor_noise_cpu_s(returns: int, repeats: int = 20) -> float:
    """CPU seconds to draw ``returns`` Gaussian range errors (numpy's generator, as the sweep does)."""
    rng = np.random.default_rng(0)
    c = time.process_time()
    for _ in range(repeats):
        rng.standard_normal(returns)
    return (time.process_time() - c) / repeats


def _rss_mb() -> float:
    """The process's resident memory now, MB (Linux /proc; the peak is ``peak_rss_mb``)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def tiled_city(min_triangles: int, seed: int = 1):
    """Whole ``city`` scenes (seeds seed, seed + 1, ...) side by side on a 520 m x 340 m grid until the
    world has ``min_triangles``; returns (World, the first tile's trajectory)."""
    import scenes

    parts, tris, k, traj = [], 0, 0, None
    while tris < min_triangles:
        scene = scenes.build_scene("city", seed=seed + k)
        traj = traj or scene.trajectory
        shift = np.array([520.0 * (k % 4), 340.0 * (k // 4), 0.0])
        parts.append((scene.vertices + shift, scene.faces, scene.face_object_id, scene.object_labels))
        tris += len(scene.faces)
        k += 1
    verts, faces, ids, labels, vbase, obase = [], [], [], [], 0, 0
    for v, f, o, lab in parts:
        verts.append(v)
        faces.append(f + vbase)
        ids.append(o + obase)
        labels += list(lab)
        vbase += len(v)
        obase += len(lab)
    return World(np.vstack(verts), np.vstack(faces), np.concatenate(ids), labels, f"{k} city tiles"), traj


def bench_big_world(min_triangles: int, sensor_name: str, frames: int, tmp_root: str | None) -> None:
    """Load a >= ``min_triangles`` world from a PLY file as ``salo simulate --mesh`` does, and simulate along it."""
    from simlidar.world import load_world, save_world_ply

    sensor = load_sensor(sensor_name)
    t = time.perf_counter()
    world, traj = tiled_city(min_triangles)
    print(f"big world: {len(world.faces):,} triangles, {len(world.object_labels):,} objects "
          f"(built from scenes in {time.perf_counter() - t:.1f} s)")
    with tempfile.TemporaryDirectory(dir=tmp_root) as tmp:
        ply = Path(tmp) / "world.ply"
        save_world_ply(world, ply)
        del world
        rss0 = _rss_mb()
        t = time.perf_counter()
        loaded = load_world(ply)
        t_load = time.perf_counter() - t
        t = time.perf_counter()
        sim = SweepSimulator(loaded, sensor, seed=0)
        t_bvh = time.perf_counter() - t
        rss_mesh = _rss_mb()
        print(f"  PLY {ply.stat().st_size / 1e6:.0f} MB: load {t_load:.1f} s, BVH and tables {t_bvh:.1f} s; "
              f"resident memory {rss0:.0f} MB before, {rss_mesh:.0f} MB with the world loaded")
        rss = {}

        def on_frame(k, scan):
            if k + 1 in (frames // 10, frames // 2, frames):
                rss[k + 1] = _rss_mb()

        t = time.perf_counter()
        simulate_sequence(loaded, traj, sensor, Path(tmp) / "seq", frames=frames, simulator=sim, on_frame=on_frame,
                          t_start=5.0)
        dt = time.perf_counter() - t
    print(f"  {frames} frames of {sensor.name} written: {frames / dt:.1f} sweeps/s (whole call, inside check "
          f"included); resident memory after " + ", ".join(f"{k} frames {v:.0f} MB" for k, v in rss.items())
          + f"; peak {peak_rss_mb():.0f} MB")


def bench_memory(world: World, sensor_name: str, frames: int) -> None:
    sensor = load_sensor(sensor_name)
    rss = {}

    def on_frame(k, scan):
        if k + 1 in (frames // 10, frames):
            rss[k + 1] = peak_rss_mb()

    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        simulate_sequence(world, straight_path(), sensor, Path(tmp) / "seq", frames=frames, on_frame=on_frame)
        dt = time.perf_counter() - t
        size = sum(p.stat().st_size for p in (Path(tmp) / "seq").rglob("*") if p.is_file())
    a, b = frames // 10, frames
    print(f"{frames}-frame {sensor.name} sequence: {dt:.0f} s ({frames / dt:.1f} frames/s incl. writing), "
          f"{size / 1e9:.2f} GB on disk")
    print(f"  peak RSS after {a} frames: {rss[a]:.0f} MB; after {b} frames: {rss[b]:.0f} MB "
          f"(ratio {rss[b] / rss[a]:.3f})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sensor", default="salo32")
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--memory", type=int, default=0, help="frames of the streaming-memory run (0: skip)")
    ap.add_argument("--memory-sensor", default="vlp16")
    ap.add_argument("--e2e-frames", type=int, default=100, help="frames of the end-to-end run (0: skip)")
    ap.add_argument("--e2e-scene", default="city")
    ap.add_argument("--e2e-seed", type=int, default=3)
    ap.add_argument("--big-world", type=int, default=0, help="triangles of the tiled-city world run (0: skip)")
    ap.add_argument("--big-frames", type=int, default=300, help="frames of the big-world run")
    ap.add_argument("--tmp", help="folder for the end-to-end sequence (default: the system's temporary folder)")
    ap.add_argument("--imu", action="store_true", help="run the end-to-end simulation again with the IMU on")
    ap.add_argument("--weather-repeats", type=int, default=20,
                    help="sweeps of each weather run (0: skip the weather's cost)")
    ap.add_argument("--actors-repeats", type=int, default=20,
                    help="sweeps of each moving-actor run, 20 and 100 actors against none (0: skip)")
    args = ap.parse_args()
    t = time.perf_counter()
    world = bench_world()
    print(f"world: {len(world.faces)} triangles, built in {time.perf_counter() - t:.2f} s")
    bench_sweep(world, args.sensor, args.repeats)
    if args.e2e_frames:
        bench_end_to_end(args.e2e_scene, args.e2e_seed, args.sensor, args.e2e_frames, args.tmp, args.imu)
    if args.weather_repeats:
        bench_weather(args.e2e_scene, args.e2e_seed, args.sensor, args.weather_repeats)
    if args.actors_repeats:
        bench_actors(args.e2e_scene, args.e2e_seed, args.sensor, args.actors_repeats)
    if args.big_world:
        bench_big_world(args.big_world, args.sensor, args.big_frames, args.tmp)
    if args.memory:
        bench_memory(world, args.memory_sensor, args.memory)


if __name__ == "__main__":
    main()
