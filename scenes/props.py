"""Street furniture and natural objects, each a list of parts in a local frame.

Local frame: origin on the ground at the object's foot, x along its length
(a car's forward axis, a sign's facing direction), z up; place with
``geometry.place`` (yaw about z, then translate). Sizes are typical real ones.
"""

from __future__ import annotations

import numpy as np

from . import geometry as g


def car(rng: np.random.Generator) -> g.Part:
    """A passenger car about 4.2-4.8 m x 1.75-1.85 m x 1.45 m: body, cabin, four wheels."""
    length = rng.uniform(4.2, 4.8)
    width = rng.uniform(1.75, 1.85)
    body_h = 0.7
    clearance = 0.25
    cabin_h = rng.uniform(0.5, 0.6)
    parts = [g.box((length, width, body_h), (0.0, 0.0, clearance + body_h / 2))]
    # Cabin: a trapezoid prism, narrower at the roof (windscreen and rear window slopes).
    zb, zt = clearance + body_h, clearance + body_h + cabin_h
    xb0, xb1 = -0.35 * length, 0.2 * length
    xt0, xt1 = -0.25 * length, 0.05 * length
    yb, yt = 0.47 * width, 0.4 * width
    pts = np.array([[x, y, zb] for x in (xb0, xb1) for y in (-yb, yb)]
                   + [[x, y, zt] for x in (xt0, xt1) for y in (-yt, yt)])
    parts.append(g.convex(pts))
    for sx in (-0.32 * length, 0.32 * length):
        for sy in (-0.5 * width + 0.12, 0.5 * width - 0.12):
            v, f = g.cylinder(0.32, 0.22, sections=10)
            # Lay the wheel's axis along y: rotate z -> y about x.
            v = v - np.array([0.0, 0.0, 0.11])
            v = np.stack([v[:, 0], v[:, 2], -v[:, 1]], axis=1) + np.array([sx, sy, 0.32])
            parts.append((v, f))
    return g.merge(parts)


def street_light(height_m: float = 7.0, arm_m: float = 1.5) -> g.Part:
    """A pole with an arm reaching toward +x and a lamp head at its end."""
    return g.merge([
        g.cylinder(0.09, height_m, sections=8),
        g.box((arm_m, 0.08, 0.08), (arm_m / 2, 0.0, height_m - 0.1)),
        g.box((0.6, 0.3, 0.15), (arm_m, 0.0, height_m - 0.22)),
    ])


def bollard_pole(height_m: float = 3.0) -> g.Part:
    """A plain pole (bollard, parking meter post, traffic light mast without head)."""
    return g.cylinder(0.06, height_m, sections=8)


def sign(height_m: float = 2.6, plate=(0.05, 0.7, 0.7)) -> tuple[g.Part, g.Part]:
    """(post, plate): a road sign facing +x."""
    post = g.cylinder(0.04, height_m, sections=6)
    face = g.box(plate, (0.08, 0.0, height_m - plate[2] / 2))
    return post, face


def tree(rng: np.random.Generator, height_m: float, crown_radius_m: float) -> tuple[g.Part, g.Part]:
    """(trunk, crown): a trunk and an irregular convex crown."""
    trunk_h = height_m * rng.uniform(0.35, 0.5)
    trunk = g.cylinder(0.12 + 0.02 * height_m, trunk_h + crown_radius_m * 0.5, sections=7)
    crown_h = height_m - trunk_h
    crown = g.blob(rng, (crown_radius_m, crown_radius_m, crown_h / 2),
                   (0.0, 0.0, trunk_h + crown_h / 2), n_points=28, jitter=0.2)
    return trunk, crown


def conifer(rng: np.random.Generator, height_m: float, radius_m: float) -> tuple[g.Part, g.Part]:
    """(trunk, crown): a spruce-like cone crown on a short trunk."""
    trunk_h = height_m * 0.2
    trunk = g.cylinder(0.15 + 0.01 * height_m, trunk_h + 0.5, sections=7)
    k = 9
    ang = np.linspace(0, 2 * np.pi, k, endpoint=False) + rng.uniform(0, 2 * np.pi)
    r = radius_m * rng.uniform(0.85, 1.15, k)
    base = np.stack([r * np.cos(ang), r * np.sin(ang), np.full(k, trunk_h)], axis=1)
    crown = g.convex(np.vstack([base, [[0.0, 0.0, height_m]]]))
    return trunk, crown


def rock(rng: np.random.Generator, size_m: float) -> g.Part:
    """An irregular boulder about ``size_m`` across, sunk a little into the ground."""
    radii = size_m / 2 * rng.uniform(0.6, 1.0, 3)
    radii[2] *= 0.7
    return g.blob(rng, radii, (0.0, 0.0, radii[2] * 0.6), n_points=18, jitter=0.3)


def shrub(rng: np.random.Generator, size_m: float) -> g.Part:
    """A low bush about ``size_m`` across."""
    radii = np.array([size_m / 2, size_m / 2 * rng.uniform(0.7, 1.0), size_m * 0.35])
    return g.blob(rng, radii, (0.0, 0.0, radii[2] * 0.8), n_points=20, jitter=0.3)
