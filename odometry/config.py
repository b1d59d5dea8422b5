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
(``match: {target: map}``, ``odometry.local_map``) instead of the previous scan,
with poles (``poles: {enabled: true}``, ``odometry.poles``) beside the planes.

The keys are grouped by stage, as nested sections (``paramspec``): in YAML a
mapping per stage, on the command line a dotted key (``--set
ncf.max_normal_std_deg=3``, ``--set deskew.enabled=false``). Each key is
declared once, with its type, default, bounds and help (``salo odometry
--keys``, ``docs/parameters.md``); the rules between keys are checked in
``OdometryConfig.__post_init__``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from paramspec import ParamError, Params, assignments, differences, param, section
from simlidar.yaml_file import read_yaml

NOISE_MODELS = ("range", "isotropic")
MATCH_TARGETS = ("filtered", "map")
NCF_SCOPES = ("scan", "map", "both")
WEAK_UPDATES = ("prior", "remap")
GCR_FORMULAS = ("beam", "paper")


class ConfigError(ParamError):
    """An odometry config is invalid; the message names the file or config, the dotted key and the problem."""


class _Stage(Params):
    """A section of the config: its errors are ``ConfigError``s."""

    error = ConfigError


@dataclass(frozen=True)
class CleanParams(_Stage):
    """Preprocessing: the points kept of a raw scan, and KITTI's angle correction."""

    section_name = "clean"
    min_range_m: float = param(2.5, "points nearer than this are ignored (the ego vehicle)", min=0.0)
    max_range_m: float = param(120.0, "points farther than this are ignored (far noise)", above=0.0)
    kitti_vertical_correction_deg: float = param(
        0.0, "rotate KITTI HDL-64E points about the axis across their beam by this much (0: off; KITTI: 0.205)")
    drop_isolated: bool = param(False, "drop returns too few of whose neighbouring beams end within the tolerance "
                                "of them (fog, rain, snow: odometry/isolation.py) from the points the normals, "
                                "the ICP and the map are made of")
    isolated_only_in_weather: bool = param(
        True, "drop them only from a scan the poles' clutter statistic takes as in weather (more crowded "
        "one-return poles per beam than the poles' gate, odometry/poles.py): a clear scan keeps every return")
    isolation_columns: int = param(3, "azimuth columns either side of a return on its ring looked at (and 2 x this "
                                   "+ 2 nearest beams in direction for the returns that look leaves)", min=1)
    isolation_neighbours: int = param(2, "a return with fewer neighbours than this within the tolerance is alone",
                                      min=1)
    isolation_min_m: float = param(0.1, "the range tolerance's least value", above=0.0)
    isolation_fraction: float = param(0.02, "the range tolerance as a fraction of the return's range", min=0.0)


@dataclass(frozen=True)
class DeskewParams(_Stage):
    """De-skew: motion distortion corrected with per-point times, when the scan has them."""

    section_name = "deskew"
    enabled: bool = param(True, "de-skew with the constant-velocity motion; the scan is re-de-skewed at every "
                          "ICP step, halfway from its de-skew motion towards the estimate's")
    refinements: int = param(1, "after the ICP, redo the de-skew with the frame's own motion and register again "
                             "from its estimate, this many times (0: none, faster; weakly constrained scenes "
                             "drift more)", min=0)


@dataclass(frozen=True)
class FilterParams(_Stage):
    """Filtration (the paper's voxel grid, normals, curvature): the ICP's points."""

    section_name = "filter"
    voxel_size_m: float = param(0.35, "edge of the voxel grid whose occupied voxels' centroids are the ICP "
                                "points", above=0.0)
    normal_neighbours: int = param(12, "k of the kNN normal estimation in the raw scan", min=3)
    adjacent_ring_reach_m: float | None = param(
        4.0, "a kNN neighbourhood on one ring takes the nearer adjacent ring's points within this distance "
        "instead of its farther half (odometry/scan_lines.py; needs the sensor); null: plain kNN (the paper)",
        above=0.0)
    max_curvature: float = param(0.05, "PCL curvature above which a point is discarded", min=0.0)
    min_points: int = param(100, "fewer filtered points or matches: the frame is flagged, its pose extrapolated",
                            min=6)


@dataclass(frozen=True)
class NcfParams(_Stage):
    """The normal covariance filter (NCF, odometry/ncf.py): points whose normal is too uncertain are dropped."""

    section_name = "ncf"
    enabled: bool = param(True, "apply the normal covariance filter")
    noise_model: str = param("range", "range: Gaussian noise along each beam (sensor-aware); isotropic: the "
                             "paper's sphere", choices=NOISE_MODELS)
    point_noise_std_m: float = param(0.02, "noise std of the isotropic model (the paper's xi, used there as a "
                                     "variance)", above=0.0)
    range_noise_std_m: float | None = param(None, "range noise std of the range model (null: the sensor's)",
                                            above=0.0)
    noise_free_gaps: bool = param(True, "PCA eigen-gaps net of the noise's scatter; reject normals the noise "
                                  "alone could explain (false: the paper's linearisation)")
    max_normal_std_deg: float = param(5.0, "c_tau as an angle: reject a point whose normal's largest std is at "
                                      "least this", above=0.0)
    applies_to: str = param("scan", "whose normals it judges: the scan's (the paper), the map's (with "
                            "match.target map), or both", choices=NCF_SCOPES)


@dataclass(frozen=True)
class MatchParams(_Stage):
    """Matching and rejection: the target, the distance rejector and trimming."""

    section_name = "match"
    target: str = param("filtered", "match against the previous filtered scan (Alg. 1) or a local map of recent "
                        "scans", choices=MATCH_TARGETS)
    max_correspondence_distance_m: float = param(1.0, "the distance rejector's bound", above=0.0)
    initial_correspondence_distance_m: float = param(
        3.0, "bound of a coarse registration, untrimmed, before a sequence's first (it has no motion to "
        "extrapolate)", above=0.0)
    trim_fraction: float = param(0.2, "drop this fraction of the largest match distances (paper: 0.2)", min=0.0,
                                 below=1.0)


@dataclass(frozen=True)
class MapParams(_Stage):
    """The local map (odometry/local_map.py), when match.target is map."""

    section_name = "map"
    voxel_size_m: float = param(1.0, "edge of the map's voxels", above=0.0)
    points_per_voxel: int = param(20, "most points a map voxel holds", min=1)
    min_point_spacing_m: float = param(0.3, "a scan point closer than this to a map point is not added (0: "
                                       "every point while its voxel has room)", min=0.0)
    max_distance_m: float | None = param(None, "map points farther than this from the sensor are dropped (null: "
                                         "clean.max_range_m)", above=0.0)


@dataclass(frozen=True)
class PolesParams(_Stage):
    """Poles (odometry/poles.py): narrow objects clear of their background, matched across the road."""

    section_name = "poles"
    enabled: bool = param(False, "add each pole of the scan (a run of a ring's returns at most max_width_m across, "
                          "clearly nearer than both sides) matched to a recent pole as two horizontal "
                          "constraints, and start the first registration from the poles' offset")
    max_width_m: float = param(1.2, "widest run across the beam that counts as a pole", above=0.0)
    frames_kept: int = param(30, "poles of this many recent frames are matched against", min=1)
    clutter_filter: bool = param(True, "weather clutter is not a pole: on a scan in weather (many one-return poles "
                                 "crowded together, as fog and snow make; or a few, after scans in weather), a pole "
                                 "must stand clear of other poles and be as wide as a post, and is matched against "
                                 "once a pole of the frame before or after it confirms it; a clear scan's poles are "
                                 "kept as they are (odometry/poles.py)")
    clutter_reach: bool = param(True, "in weather, a one-return pole no other ring sees is taken for the weather's "
                                "only within the clutter's reach (1.25 x the 99th percentile of the crowded one-return "
                                "poles' ranges); false: at any range (snow reaches beyond where it is crowded)")


@dataclass(frozen=True)
class DynamicParams(_Stage):
    """The moving-object stage (odometry/dynamic.py): returns where recent scans saw through are kept out."""

    section_name = "dynamic"
    enabled: bool = param(False, "drop from the registration and the map the scan's points at places recent scans "
                          "saw through (something moved there); needs the sensor")
    history_frames: int = param(30, "how many frames back the oldest scan a point is checked against is; it is "
                                "checked against the scans 1, 2, 4, 8, ... frames back and that one", min=1)
    free_margin_m: float = param(0.5, "how far beyond a point every return around its direction must have "
                                 "reached for its place to count as seen through", above=0.0)
    window_rows: int = param(1, "rings either side of a direction whose returns must all have reached beyond "
                             "the point", min=0)
    window_columns: int = param(2, "azimuth columns either side of a direction whose returns must all have "
                                "reached beyond the point", min=0)


@dataclass(frozen=True)
class GcrParams(_Stage):
    """The geometric correspondence rejector (GCR, odometry/gcr.py)."""

    section_name = "gcr"
    enabled: bool = param(True, "apply the geometric correspondence rejector")
    formula: str = param("beam", "beam: the neighbour beam's hit on the surface (the paper's text); paper: its "
                         "printed formula, a lower bound", choices=GCR_FORMULAS)
    noise_floor_m: float = param(0.0, "lower bound on the GCR threshold (0: the paper)", min=0.0)


@dataclass(frozen=True)
class IcpParams(_Stage):
    """Estimation and termination of the ICP."""

    section_name = "icp"
    max_iterations: int = param(30, "iteration cap", min=1)
    abs_translation_tol_m: float = param(1e-3, "stop when an increment is below this and abs_rotation_tol_deg",
                                         above=0.0)
    abs_rotation_tol_deg: float = param(0.01, "stop when an increment is below this and abs_translation_tol_m",
                                        above=0.0)
    rel_tolerance: float = param(1e-3, "stop when an increment is below this fraction of the registration's "
                                 "accumulated motion", min=0.0)
    max_prediction_error_m: float = param(1.0, "an estimate farther than this from the constant-velocity "
                                          "prediction failed: flagged, pose extrapolated", above=0.0)
    max_prediction_error_deg: float = param(10.0, "an estimate turned farther than this from the prediction "
                                            "failed: flagged, pose extrapolated", above=0.0)


@dataclass(frozen=True)
class DegeneracyParams(_Stage):
    """Degeneracy (odometry/constraints.py): weakly constrained directions of motion."""

    section_name = "degeneracy"
    degenerate_eigenvalue: float = param(0.01, "flag a frame whose smallest translational eigenvalue of the "
                                         "information per match is below this", min=0.0)
    min_constraint_eigenvalue: float = param(0.01, "a direction whose scaled information per match is below "
                                             "this keeps the motion prior, and the NCF may not push one below it "
                                             "(0: neither)", min=0.0)
    weak_direction_update: str = param("prior", "prior: a motion prior blends with the data in weak directions; "
                                       "remap: they get no update", choices=WEAK_UPDATES)
    rotation_scale_m: float = param(10.0, "length L making rotation commensurate with translation (rows "
                                    "[n, (p x n) / L])", above=0.0)


@dataclass(frozen=True)
class ImuParams(_Stage):
    """The IMU between scans (odometry/inertial.py): prediction, de-skew and the weak directions' prior."""

    section_name = "imu"
    enabled: bool = param(False, "with the sequence's IMU samples: predict each scan's motion and de-skew its sweep "
                          "with the preintegrated gyroscope and accelerometer instead of constant velocity (the "
                          "prior in weakly constrained directions); without samples nothing changes")
    window_frames: int = param(20, "frames the filter of velocity, gravity and the accelerometer's bias takes "
                               "before the IMU predicts; the window over which the gyroscope's bias is fitted",
                               min=3)
    position_std_m: float = param(0.02, "the registered positions' standard deviation in the filter (a direction "
                                  "with all the information one can have)", above=0.0)
    rotation_std_deg: float = param(0.01, "the registered rotations' standard deviation in the gyroscope bias's "
                                    "fit", above=0.0)


@dataclass(frozen=True)
class OdometryConfig(Params):
    """Parameters of the ICP odometry, grouped by stage. Units in names; degrees only where named ``*_deg``.

    Each stage is a section (``cfg.ncf.max_normal_std_deg``; ``ncf:`` in YAML,
    ``ncf.max_normal_std_deg=3`` on the command line) whose keys are declared
    with their bounds and help. Why the defaults are what they are:
    docs/default-choices.md; why each key exists: docs/keys.md. The ICP's termination (1 mm, 0.01 deg) is
    an order below a frame's own error of about a centimetre: tighter only adds
    iterations. A prediction error of 1 m is 10 m/s^2 of sudden acceleration at
    10 Hz, ten times over. Rules between keys: ``clean.min_range_m`` <
    ``clean.max_range_m``; ``ncf.applies_to`` other than scan needs
    ``match.target`` map.
    """

    error = ConfigError
    section_name = "odometry config"

    name: str = param("salo", "the variant's name")
    clean: CleanParams = section(CleanParams)
    deskew: DeskewParams = section(DeskewParams)
    filter: FilterParams = section(FilterParams)
    ncf: NcfParams = section(NcfParams)
    match: MatchParams = section(MatchParams)
    map: MapParams = section(MapParams)
    poles: PolesParams = section(PolesParams)
    dynamic: DynamicParams = section(DynamicParams)
    gcr: GcrParams = section(GcrParams)
    icp: IcpParams = section(IcpParams)
    degeneracy: DegeneracyParams = section(DegeneracyParams)
    imu: ImuParams = section(ImuParams)

    def __post_init__(self) -> None:
        try:
            super().__post_init__()  # every key against its declaration; then the rules between keys
            if self.clean.min_range_m >= self.clean.max_range_m:
                raise ConfigError(f"must be < clean.max_range_m ({self.clean.min_range_m} >= "
                                  f"{self.clean.max_range_m})", "clean.min_range_m")
            if self.ncf.applies_to != "scan" and self.match.target != "map":
                raise ConfigError(f"'{self.ncf.applies_to}' needs match.target: map (there is no map to judge)",
                                  "ncf.applies_to")
        except ConfigError as exc:
            raise exc.at(f"odometry config '{self.name}'") from None

    def replace(self, **changes: Any) -> OdometryConfig:
        """A new validated config with some keys changed; a section's as a partial mapping, as in YAML.

        ``cfg.replace(name="x", gcr={"enabled": False}, match={"trim_fraction": 0.0})``.
        Unknown keys and bad values raise ``ConfigError``.
        """
        return type(self).from_dict(changes, f"odometry config '{self.name}'", base=self)

    def to_yaml(self) -> str:
        return yaml.safe_dump(self.to_dict(), sort_keys=False)


BL = OdometryConfig(name="bl", ncf={"enabled": False}, gcr={"enabled": False})
NCF = OdometryConfig(name="ncf", ncf={"enabled": True}, gcr={"enabled": False})
SALO = OdometryConfig(name="salo", ncf={"enabled": True}, gcr={"enabled": True})
BL_MAP = BL.replace(name="bl-map", match={"target": "map"}, poles={"enabled": True})
NCF_MAP = NCF.replace(name="ncf-map", match={"target": "map"}, ncf={"applies_to": "map"}, poles={"enabled": True})
SALO_MAP = SALO.replace(name="salo-map", match={"target": "map"}, ncf={"applies_to": "map"}, poles={"enabled": True})
VARIANTS = {c.name: c for c in (BL, NCF, SALO, BL_MAP, NCF_MAP, SALO_MAP)}
# What ``salo odometry`` runs without --variant (chosen on the generalisation suite's tuning
# seeds; docs/default-choices.md).
DEFAULT_VARIANT = "salo-map"


def variant(name: str) -> OdometryConfig:
    """The named config of a variant: bl, ncf, salo (the paper's table) or their -map twins."""
    if name not in VARIANTS:
        raise ConfigError(f"unknown odometry variant '{name}' (known: {', '.join(VARIANTS)})")
    return VARIANTS[name]


def variant_changes() -> dict[str, dict]:
    """Each variant's changes to the defaults (the salo variant's), as ``{dotted key: value}``."""
    return {name: {k: v for k, v in differences(c, SALO).items() if k != "name"} for name, c in VARIANTS.items()}


# Keys that were measured, not kept, and removed; what a config that still sets one is told.
REMOVED_KEYS = {
    "filter.source_voxel_size_m": "the source thinned to a coarser voxel lost accuracy on the tuning seeds",
    "match.cold_start_from_rest": "refining standing still at the cold start moved highway starts both ways",
    "deskew.refinement_iterations": "capping a refinement's ICP raised the tuning seeds' mean t_err",
    "deskew.joint": "the de-skew is redone at every ICP step, always",
    "map.cold_start_target": "a map variant's cold start registers against both the map and the scan, always",
}


def refuse_removed_keys(data: Any, origin: str) -> None:
    """ConfigError when a YAML-style mapping sets a key of ``REMOVED_KEYS`` (or ``match.target: raw``)."""
    if not isinstance(data, dict):
        return
    record = "docs/default-choices.md, 'Measured and not kept'"
    for dotted, why in REMOVED_KEYS.items():
        section, key = dotted.split(".")
        if isinstance(data.get(section), dict) and key in data[section]:
            raise ConfigError(f"was removed ({why}; {record})", dotted).at(origin)
    if isinstance(data.get("match"), dict) and data["match"].get("target") == "raw":
        raise ConfigError(f"'raw' was removed (a raw scan as the target: {record}); use filtered or map",
                          "match.target").at(origin)


def changes_from_assignments(pairs, origin: str = "--set") -> dict:
    """``KEY=VALUE`` texts with dotted keys (``ncf.max_normal_std_deg=3``) -> the changes, nested by stage
    as a config YAML holds them, each value converted and checked by its key's declaration.
    Overlay them with ``config_from_dict(changes, base=...)``. Raises ConfigError naming the key."""
    given = assignments(pairs, origin)
    refuse_removed_keys(given, origin)
    return OdometryConfig.schema().read(given, origin, coerce=True, partial=True, error=ConfigError)


def config_from_dict(data: Any, base: OdometryConfig | None = None, origin: str = "config", *,
                     coerce: bool = False) -> OdometryConfig:
    """Overlay a YAML-style mapping (a section per stage, any subset of the keys) on ``base``.

    base: default the variant named in ``data``, else salo. coerce: the values
    may be command-line text (``paramspec.assignments``). Errors name ``origin``.
    """
    refuse_removed_keys(data, origin)
    if base is None:
        name = data.get("name") if isinstance(data, dict) else None
        base = variant(name) if name in VARIANTS else SALO
    return OdometryConfig.from_dict(data, origin, coerce=coerce, base=base)


def load_config(path: str | Path, base: OdometryConfig | None = None) -> OdometryConfig:
    """Read an odometry config YAML file (any subset of the parameters)."""
    data = read_yaml(path, ConfigError, "config") or {}
    return config_from_dict(data, base, origin=str(path))
