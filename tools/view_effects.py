"""Pictures of the sensor effects (``simlidar.sensor``: beam divergence, incidence noise, intensity).

    python -m tools.view_effects --out out/effects     # mixed_pixels.png, incidence_noise.png, intensity.png

Each picture is simulated in a small analytic world, so what it shows can be
checked by eye against the model (``simlidar.sweep``'s module doc):

- ``mixed_pixels.png``: top-down, one ring of salo32 with a 0.3 deg beam at a
  building's corner with a recessed door 0.4 m deep and a wall 8 m behind: the
  points the beam's echoes put between the surfaces (the recess, within one echo)
  and on the wrong one (the corner, two echoes: the strongest wins), coloured by
  measured minus true range;
- ``incidence_noise.png``: range residual against the angle of incidence on flat
  ground and a tilted wall, with the model's sigma0 / cos(incidence), clipped;
- ``intensity.png``: intensity against the angle of incidence for two objects
  of different reflectance, with the formula, and the scan coloured by intensity.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np


def _world(parts: list[tuple[np.ndarray, np.ndarray, str]]):
    from simlidar.world import World

    verts, faces, ids, labels, base = [], [], [], [], 0
    for k, (v, f, label) in enumerate(parts):
        verts.append(v)
        faces.append(f + base)
        ids.append(np.full(len(f), k))
        labels.append(label)
        base += len(v)
    return World(np.vstack(verts), np.vstack(faces), np.concatenate(ids), labels, "effects")


def _box(lo, hi):
    import trimesh

    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    m = trimesh.creation.box(hi - lo)
    m.apply_translation((lo + hi) / 2)
    return np.asarray(m.vertices), np.asarray(m.faces)


def _still(z: float = 0.0):
    from simlidar.trajectory import SampledTrajectory

    T = np.eye(4)
    T[2, 3] = z
    return SampledTrajectory(np.array([0.0]), T[None])


def mixed_pixels(out: Path) -> Path:
    """A building corner with a recess and a far wall, one ring, with and without divergence."""
    import matplotlib.pyplot as plt

    from simlidar.sensor import load_sensor
    from simlidar.sweep import SweepSimulator

    world = _world([
        (*_box((12, -20, -3), (20, -1.0, 10)), "building"),  # facade at x = 12, corner at y = -1
        (*_box((12.4, -1.0, -3), (20, 0.6, 10)), "building"),  # a door recessed 0.4 m, y -1 .. 0.6
        (*_box((12, 0.6, -3), (20, 2.0, 10)), "building"),  # facade again, corner at y = 2
        (*_box((20, -40, -3), (21, 40, 10)), "wall"),  # a wall 8 m behind
    ])
    base = load_sensor("salo32").with_overrides(range_noise_std_m=0.0)
    runs = {"no divergence": base}
    for mode in ("strongest", "first", "last"):
        runs[mode] = base.with_overrides(beam_divergence_deg=0.3, beam_subrays=16, return_mode=mode)
    got = {}
    for name, sensor in runs.items():
        scan = SweepSimulator(world, sensor, seed=0, motion_distortion=False).sweep(_still(), 0.0)
        ring = scan.ring == 31  # the highest ring: level, above the ground
        xyz = scan.xyz[ring]
        got[name] = (xyz, np.degrees(np.arctan2(xyz[:, 1], xyz[:, 0])), scan.range_m[ring],
                     (scan.range_m - scan.true_range_m)[ring])
    fig, axes = plt.subplots(1, 3, figsize=(16, 5.2), gridspec_kw={"width_ratios": [1.1, 1, 1]})
    xyz, _, _, err = got["strongest"]
    window = (xyz[:, 0] > 10) & (xyz[:, 0] < 22) & (np.abs(xyz[:, 1]) < 4)
    off = window & (np.abs(err) > 0.01)
    ax = axes[0]
    ax.scatter(xyz[window, 1], xyz[window, 0], s=4, color="0.6", label="returns")
    ax.scatter(xyz[off, 1], xyz[off, 0], s=40, facecolors="none", edgecolors="C3",
               label="off their surface by > 1 cm (strongest echo)")
    ax.set_xlim(4, -4)
    ax.set_xlabel("y (left), m")
    ax.set_ylabel("x (ahead), m")
    ax.set_title("top-down, one ring: facade 12 m, door 12.4 m, wall 20 m", fontsize=10)
    ax.legend(fontsize=8, loc="center")
    ax.grid(alpha=0.3)
    styles = {"no divergence": ("x", 45, "0.3"), "strongest": ("o", 22, "C0"), "first": ("v", 22, "C2"),
              "last": ("^", 22, "C1")}
    for ax, (edge, what) in zip(axes[1:], (
            (np.degrees(np.arctan2(0.6, 12.4)), "door jamb: 12.4 m door / 12 m facade, one echo: between"),
            (np.degrees(np.arctan2(2.0, 12.0)), "corner: 12 m facade / 20 m wall, two echoes: the mode picks")),
            strict=True):
        for name, (_, az, rng_, _) in got.items():
            sel = np.abs(az - edge) < 0.45
            marker, size, color = styles[name]
            ax.scatter(az[sel], rng_[sel], marker=marker, s=size, color=color, alpha=0.8,
                       label=name if name == "no divergence" else f"0.3 deg beam, {name} echo")
        ax.axvline(edge, color="k", lw=0.5, ls=":")
        ax.set_xlabel("azimuth, deg (dotted: the edge)")
        ax.set_ylabel("measured range, m")
        ax.set_title(what, fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="center left")
    fig.suptitle(f"Mixed pixels, salo32 with a 0.3 deg beam (16 sub-rays, 0.5 m echo separation): {int(off.sum())} "
                 f"of {int(window.sum())} returns of the top ring off their surface near these edges", fontsize=11)
    fig.tight_layout()
    path = out / "mixed_pixels.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def incidence_noise(out: Path) -> Path:
    """Residuals against incidence on flat ground, with the model's curve."""
    import matplotlib.pyplot as plt

    from simlidar.sensor import load_sensor
    from simlidar.sweep import SweepSimulator

    sigma0, factor = 0.01, 5.0
    ground = _box((-150, -150, -1), (150, 150, 0))
    wall = _box((-1, -150, 0), (0, 150, 30))
    import trimesh

    tilt = trimesh.transformations.rotation_matrix(np.radians(35), (0, 1, 0))
    wall_v = (np.c_[wall[0], np.ones(len(wall[0]))] @ tilt.T)[:, :3] + (25, 0, 0)
    world = _world([(*ground, "ground"), (wall_v, wall[1], "wall")])
    sensor = load_sensor("vlp16").with_overrides(range_noise_std_m=sigma0, incidence_noise_max_factor=factor)
    sim = SweepSimulator(world, sensor, seed=2, motion_distortion=False)
    scans = [sim.sweep(_still(2.0), 0.1 * k, frame_index=k) for k in range(4)]
    res = np.concatenate([s.range_m - s.true_range_m for s in scans])
    cos = np.concatenate([np.abs(np.einsum("ij,ij->i", s.xyz / np.linalg.norm(s.xyz, axis=1, keepdims=True),
                                           s.normal)) for s in scans])
    angle = np.degrees(np.arccos(np.clip(cos, 0, 1)))
    fig, ax = plt.subplots(figsize=(8, 5))
    ax.scatter(angle, res, s=1, alpha=0.15, color="0.4", label="returns (ground and a wall tilted 35 deg)")
    edges = np.arange(0, 91, 3.0)
    mid, std = [], []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        sel = (angle >= lo) & (angle < hi)
        if sel.sum() > 200:
            mid.append((lo + hi) / 2)
            std.append(res[sel].std())
    a = np.linspace(0, 89.5, 300)
    model = sigma0 * np.minimum(1 / np.cos(np.radians(a)), factor)
    ax.plot(mid, std, "o", color="C3", label="measured std per 3 deg bin")
    ax.plot(mid, -np.asarray(std), "o", color="C3")
    ax.plot(a, model, color="C0", label=f"model: {sigma0 * 100:g} cm / cos(incidence), at most {factor:g}x")
    ax.plot(a, -model, color="C0")
    ax.set_xlabel("angle of incidence, deg")
    ax.set_ylabel("measured - true range, m")
    ax.set_ylim(-0.25, 0.25)
    ax.legend(loc="upper left", fontsize=9)
    ax.grid(alpha=0.3)
    ax.set_title("Range noise growing with incidence (vlp16, incidence_noise_max_factor 5)")
    path = out / "incidence_noise.png"
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def intensity(out: Path) -> Path:
    """Intensity against incidence for two reflectances, and a top-down view coloured by intensity."""
    import matplotlib.pyplot as plt
    import trimesh

    from simlidar.sensor import load_sensor
    from simlidar.sweep import SweepSimulator

    ramp = trimesh.creation.box((12.0, 8.0, 0.2))  # a road ramp tilted 40 deg, behind-right of the sensor
    ramp.apply_transform(trimesh.transformations.rotation_matrix(np.radians(40), (0, 1, 0)))
    ramp.apply_translation((-9.0, -6.0, 1.0))
    road_v = np.vstack([_box((-60, -60, -1), (60, 60, 0))[0], ramp.vertices])
    road_f = np.vstack([_box((-60, -60, -1), (60, 60, 0))[1], ramp.faces + 8])
    world = _world([(road_v, road_f, "road"),
                    (*_box((8, -30, 0), (9, 30, 8)), "wall")]).with_reflectance({"road": 0.15, "wall": 0.8})
    k = 2.0
    sensor = load_sensor("vlp16").with_overrides(intensity_incidence_exponent=k)
    scan = SweepSimulator(world, sensor, seed=0, motion_distortion=False).sweep(_still(1.8), 0.0)
    beam = scan.xyz / np.linalg.norm(scan.xyz, axis=1, keepdims=True)
    cos = np.abs(np.einsum("ij,ij->i", beam, scan.normal))
    angle = np.degrees(np.arccos(np.clip(cos, 0, 1)))
    falloff = np.minimum(1.0, (sensor.intensity_range_ref_m / scan.range_m) ** 2)
    fig, (ax, top) = plt.subplots(1, 2, figsize=(13, 5))
    a = np.linspace(0, 90, 200)
    for obj, name, color in ((0, "road and a 40 deg ramp", "C0"), (1, "wall", "C1")):
        sel = scan.object_id == obj
        refl = world.object_reflectance[obj]
        ax.scatter(angle[sel], scan.intensity[sel] / falloff[sel], s=3, color=color, alpha=0.5,
                   label=f"{name} (reflectance {refl:g})")
        ax.plot(a, refl * np.cos(np.radians(a)) ** k, color="k" if obj else "0.4", lw=1,
                label=f"{refl:g} x cos^{k:g}")
    ax.set_xlabel("angle of incidence, deg")
    ax.set_ylabel("intensity / min(1, (10 m / r)^2)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    ax.set_title("intensity = reflectance x |cos a|^2 x min(1, (10 m / r)^2)", fontsize=10)
    sc = top.scatter(scan.xyz[:, 1], scan.xyz[:, 0], c=scan.intensity, s=1, cmap="viridis")
    top.set_aspect("equal")
    top.set_xlim(20, -20)
    top.set_ylim(-12, 20)
    top.set_xlabel("y (left), m")
    top.set_ylabel("x (ahead), m")
    top.set_title("one vlp16 scan: a bright wall at 8 m over dark road", fontsize=10)
    fig.colorbar(sc, ax=top, label="intensity")
    path = out / "intensity.png"
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main(argv: list[str] | None = None) -> None:
    import matplotlib

    matplotlib.use("Agg")
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("out/effects"), help="folder for the PNGs (default out/effects)")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    for make in (mixed_pixels, incidence_noise, intensity):
        print(make(args.out))  # noqa: T201 - a script that reports what it wrote


if __name__ == "__main__":
    main()
