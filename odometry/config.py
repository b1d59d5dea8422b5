"""The odometry's parameters: one frozen, validated config; YAML in and out; named variants.

The paper (Sec. III, Alg. 1) fixes the structure and a few numbers: trimming of
the 20 % largest match distances, constant-velocity initialisation, 5-15 % of a
scan's points kept by the filters. It does not publish voxel size, k, c_tau,
curvature or termination thresholds; our defaults for those are chosen for a
32-beam automotive lidar and documented field by field.

Variants (the rows of the paper's Table I):

- ``bl``:   baseline: voxel grid, kNN normals, curvature filter; distance
            rejector and trimming; point-to-plane.
- ``ncf``:  ``bl`` + the normal covariance filter.
- ``salo``: ``ncf`` + the geometric correspondence rejector.

Each has a scan-to-map twin (``bl-map``, ``ncf-map``, ``salo-map``): the same
filters and rejectors, registered against a local map of recent scans
(``match_target: map``, ``odometry.local_map``) instead of the previous scan.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import yaml

from simlidar.yaml_file import read_yaml

NOISE_MODELS = ("range", "isotropic")
MATCH_TARGETS = ("filtered", "raw", "map")
NCF_SCOPES = ("scan", "map", "both")
WEAK_UPDATES = ("prior", "remap")
GCR_FORMULAS = ("beam", "paper")


class ConfigError(ValueError):
    """An odometry config is invalid; the message names the key and the problem."""


@dataclass(frozen=True)
class OdometryConfig:
    """Parameters of the ICP odometry. Units in names; degrees only where named ``*_deg``.

    Filtration (paper: voxel grid, normals + NCF, curvature):
        voxel_size_m: edge of the voxel grid whose occupied-voxel centroids are the
            ICP points.
        normal_neighbours: k of the kNN normal estimation in the raw scan.
        ncf: apply the normal covariance filter.
        ncf_noise_model: "range" (Gaussian range noise along each beam, the
            sensor-aware model) or "isotropic" (the paper's sphere).
        ncf_point_noise_std_m: noise standard deviation for the isotropic model
            (the paper's xi, which it uses as a variance: here it is a std, m).
        ncf_range_noise_std_m: range noise std for the "range" model; None takes
            the sensor's ``range_noise_std_m``.
        ncf_noise_free_gaps: take the PCA eigen-gaps net of the noise's expected scatter and
            reject normals the noise alone could explain (``odometry.ncf``); False is the
            paper's plain linearisation at the observed neighbourhood.
        ncf_max_normal_std_deg: c_tau as an angle: a point is rejected when the
            largest eigenvalue of its normal covariance >= radians(this)^2.
        ncf_applies_to: which normals the NCF judges: the "scan"'s own (the paper; in
            scan-to-scan these become the next target's, the ones the cost uses), or, with
            a map target, the "map"'s (the ones the cost then uses: each neighbour's noise
            along the beam that measured it), or "both".
        max_curvature: PCL curvature above which a point is discarded.
    Preprocessing:
        min_range_m, max_range_m: points outside are ignored (ego vehicle, far noise).
        deskew: correct motion distortion with the constant-velocity motion when
            per-point times are known.
        deskew_refinements: after the ICP, redo the de-skew with this frame's own
            estimated motion and refine, this many times (0 = the previous motion only).
        kitti_vertical_correction_deg: rotate KITTI HDL-64E points about the axis
            perpendicular to their beam by this much (0 = off; 0.205 for KITTI).
    Matching and rejection:
        match_target: match against the previous "filtered" scan (Alg. 1), its
            "raw" (de-skewed) points, or a local "map" of recent scans (``odometry.local_map``).
        map_voxel_size_m, map_points_per_voxel: the map's voxels and how many points
            each holds at most.
        map_max_distance_m: map points farther than this from the sensor are dropped
            (None: ``max_range_m``).
        max_correspondence_distance_m: the distance rejector.
        initial_correspondence_distance_m: the bound of a coarse registration, without
            trimming, before the first one (which has no motion to extrapolate: at 10-30 m/s
            the sensor moves 1-3 m per frame).
        trim_fraction: drop this fraction of the largest distances (paper: 0.2).
        gcr: apply the geometric correspondence rejector.
        gcr_formula: "beam" (the neighbour beam's hit on the surface, as the paper's
            text describes) or "paper" (its printed formula, a lower bound).
        gcr_noise_floor_m: lower bound on the GCR threshold (0 = the paper).
    Estimation and termination:
        max_iterations: iteration cap.
        abs_translation_tol_m, abs_rotation_tol_deg: stop when an increment is
            smaller than both (1 mm, 0.01 deg: an order below a frame's own error of
            about a centimetre; tighter only adds iterations, measured in the README).
        rel_tolerance: stop when the increment is below this fraction of the
            accumulated motion of this registration.
        min_points: fewer filtered points or matches than this: the frame is
            flagged and its pose extrapolated.
        max_prediction_error_m, max_prediction_error_deg: an estimate farther than this
            from the constant-velocity prediction (10 m/s^2 of sudden acceleration at
            10 Hz is 0.1 m) is a failed registration: flagged, pose extrapolated.
        degenerate_eigenvalue: flag a frame whose smallest translational
            eigenvalue of the per-match information (H / N) is below this.
    Degeneracy (``odometry.constraints``):
        min_constraint_eigenvalue: a direction of motion whose scaled information per
            match is below this is weakly constrained: the ICP holds it to the motion
            prior (``weak_direction_update``) and the NCF may not push a direction below
            it (0 = neither).
        weak_direction_update: "prior" (a constant-velocity motion prior of that
            information per match: weak directions blend data and prior) or "remap"
            (solution remapping: weak directions get no update at all).
        rotation_scale_m: the length L that makes rotation commensurate with
            translation in those eigenvalues (rows ``[n, (p x n) / L]``).
    """

    name: str = "salo"
    voxel_size_m: float = 0.35
    normal_neighbours: int = 12
    ncf: bool = True
    ncf_noise_model: str = "range"
    ncf_point_noise_std_m: float = 0.02
    ncf_range_noise_std_m: float | None = None
    ncf_noise_free_gaps: bool = True
    ncf_max_normal_std_deg: float = 5.0
    ncf_applies_to: str = "scan"
    max_curvature: float = 0.05
    min_range_m: float = 2.5
    max_range_m: float = 120.0
    deskew: bool = True
    deskew_refinements: int = 2
    kitti_vertical_correction_deg: float = 0.0
    match_target: str = "filtered"
    map_voxel_size_m: float = 1.0
    map_points_per_voxel: int = 20
    map_max_distance_m: float | None = None
    max_correspondence_distance_m: float = 1.0
    initial_correspondence_distance_m: float = 3.0
    trim_fraction: float = 0.2
    gcr: bool = True
    gcr_formula: str = "beam"
    gcr_noise_floor_m: float = 0.0
    max_iterations: int = 30
    abs_translation_tol_m: float = 1e-3
    abs_rotation_tol_deg: float = 0.01
    rel_tolerance: float = 1e-3
    min_points: int = 100
    max_prediction_error_m: float = 1.0
    max_prediction_error_deg: float = 10.0
    degenerate_eigenvalue: float = 0.01
    min_constraint_eigenvalue: float = 0.0
    weak_direction_update: str = "prior"
    rotation_scale_m: float = 10.0

    def __post_init__(self) -> None:
        def fail(key: str, problem: str) -> None:
            raise ConfigError(f"odometry config '{self.name}': key '{key}' {problem}")

        positive = ("voxel_size_m", "ncf_point_noise_std_m", "ncf_max_normal_std_deg", "max_range_m",
                    "max_correspondence_distance_m", "initial_correspondence_distance_m",
                    "abs_translation_tol_m", "abs_rotation_tol_deg",
                    "max_prediction_error_m", "max_prediction_error_deg", "map_voxel_size_m", "rotation_scale_m")
        for key in positive:
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, int | float) or not v > 0:
                fail(key, f"must be a number > 0, got {v!r}")
        for key in ("max_curvature", "min_range_m", "rel_tolerance", "degenerate_eigenvalue", "gcr_noise_floor_m",
                    "kitti_vertical_correction_deg", "min_constraint_eigenvalue"):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, int | float) or (key != "kitti_vertical_correction_deg"
                                                                          and v < 0):
                fail(key, f"must be a non-negative number, got {v!r}")
        if self.map_max_distance_m is not None and not self.map_max_distance_m > 0:
            fail("map_max_distance_m", f"must be > 0 or null, got {self.map_max_distance_m!r}")
        if self.ncf_range_noise_std_m is not None and not self.ncf_range_noise_std_m > 0:
            fail("ncf_range_noise_std_m", f"must be > 0 or null, got {self.ncf_range_noise_std_m!r}")
        if self.min_range_m >= self.max_range_m:
            fail("min_range_m", f"must be < max_range_m ({self.min_range_m} >= {self.max_range_m})")
        if not 0 <= self.trim_fraction < 1:
            fail("trim_fraction", f"must be in [0, 1), got {self.trim_fraction}")
        for key, lo in (("normal_neighbours", 3), ("max_iterations", 1), ("min_points", 6), ("deskew_refinements", 0),
                        ("map_points_per_voxel", 1)):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, int) or v < lo:
                fail(key, f"must be an integer >= {lo}, got {v!r}")
        if self.ncf_noise_model not in NOISE_MODELS:
            fail("ncf_noise_model", f"must be one of {', '.join(NOISE_MODELS)}, got {self.ncf_noise_model!r}")
        if self.gcr_formula not in GCR_FORMULAS:
            fail("gcr_formula", f"must be one of {', '.join(GCR_FORMULAS)}, got {self.gcr_formula!r}")
        if self.match_target not in MATCH_TARGETS:
            fail("match_target", f"must be one of {', '.join(MATCH_TARGETS)}, got {self.match_target!r}")
        if self.weak_direction_update not in WEAK_UPDATES:
            fail("weak_direction_update",
                 f"must be one of {', '.join(WEAK_UPDATES)}, got {self.weak_direction_update!r}")
        if self.ncf_applies_to not in NCF_SCOPES:
            fail("ncf_applies_to", f"must be one of {', '.join(NCF_SCOPES)}, got {self.ncf_applies_to!r}")
        if self.ncf_applies_to != "scan" and self.match_target != "map":
            fail("ncf_applies_to", f"'{self.ncf_applies_to}' needs match_target: map (there is no map to judge)")
        for key in ("ncf", "gcr", "deskew", "ncf_noise_free_gaps"):
            if not isinstance(getattr(self, key), bool):
                fail(key, f"must be true or false, got {getattr(self, key)!r}")

    def replace(self, **changes) -> OdometryConfig:
        """A new validated config with some fields changed."""
        unknown = sorted(set(changes) - {f.name for f in dataclasses.fields(self)})
        if unknown:
            raise ConfigError(f"odometry config: '{unknown[0]}' is not a parameter")
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def to_yaml(self) -> str:
        return yaml.safe_dump(self.to_dict(), sort_keys=False)


BL = OdometryConfig(name="bl", ncf=False, gcr=False)
NCF = OdometryConfig(name="ncf", ncf=True, gcr=False)
SALO = OdometryConfig(name="salo", ncf=True, gcr=True)
BL_MAP = BL.replace(name="bl-map", match_target="map")
NCF_MAP = NCF.replace(name="ncf-map", match_target="map", ncf_applies_to="map")
SALO_MAP = SALO.replace(name="salo-map", match_target="map", ncf_applies_to="map")
VARIANTS = {c.name: c for c in (BL, NCF, SALO, BL_MAP, NCF_MAP, SALO_MAP)}
# What ``salo odometry`` runs without --variant (chosen on the generalisation suite's tuning
# seeds; README "The method, and our choices").
DEFAULT_VARIANT = "salo-map"


def variant(name: str) -> OdometryConfig:
    """The named config of a variant: bl, ncf, salo (the paper's table) or their -map twins."""
    if name not in VARIANTS:
        raise ConfigError(f"unknown odometry variant '{name}' (known: {', '.join(VARIANTS)})")
    return VARIANTS[name]


def config_from_dict(data: dict, base: OdometryConfig | None = None, origin: str = "config") -> OdometryConfig:
    """Overlay a YAML-style dict on ``base`` (default: the variant named in ``data``, else salo)."""
    if not isinstance(data, dict):
        raise ConfigError(f"{origin}: expected a mapping of odometry parameters")
    if base is None:
        base = variant(data["name"]) if data.get("name") in VARIANTS else SALO
    try:
        return base.replace(**data)
    except (ConfigError, TypeError) as exc:
        raise ConfigError(f"{origin}: {exc}") from None


def load_config(path: str | Path, base: OdometryConfig | None = None) -> OdometryConfig:
    """Read an odometry config YAML file (any subset of the parameters)."""
    data = read_yaml(path, ConfigError, "config") or {}
    return config_from_dict(data, base, origin=str(path))
