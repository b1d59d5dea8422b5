"""The rejector study: the paper's Sec. IV-A protocol (Fig. 3) on simulated scan pairs.

Protocol (as the paper's, on simulated data):

- ``pairs`` consecutive scan pairs (target = frame k - 1, source = frame k) are
  drawn at random (seeded) from the study's sequences (default: the table's
  three city sequences).
- Both scans are de-skewed with the true motion (the simulator's poses; the
  paper's data was de-skewed by the vehicle's odometry) and filtered as the
  odometry does (voxel grid, kNN normals, NCF, curvature: the ``salo``
  config). The source is the filtered scan; the target is either the filtered
  previous scan (``match.target: filtered``, Alg. 1) or the previous de-skewed
  raw scan with normals estimated where matched (``odometry.targets.raw_scan_target``;
  no registration's target, as it came out of this study).
- Or the target is a local map (``match.target: map``, ``map_target``): the
  ``map_frames`` scans before the source, filtered as the odometry filters
  them for a map and inserted at their true poses into the odometry's
  ``LocalMap`` (world frame). The source is then made as the odometry makes it
  for a map, with the map variants' configs (``ncf-map``, ``salo-map``): every
  voxel centroid of the scan, without normals, its GCR thresholds set by
  ``register``'s first iteration from the map's normals at the first matches
  (so they depend on where the ICP starts: each registration and evaluation
  gets its own, from its own starting pose).
- For each noise level (l_r, l_t) the initial guess is ``T_true @ T_noise``:
  the noise rotates about a random axis (uniform on the sphere) by an angle
  uniform in [-l_r, l_r] and translates along another random axis by a length
  uniform in [-l_t, l_t]. One draw per pair and level, shared by every method.
- ICP runs from that guess with the odometry's rejection chains: "distance" =
  the baseline's (Euclidean distance 1 m, then trimming 20 %, the ``ncf``
  config), "gcr" = SALO's (distance bound, GCR, trimming, the ``salo``
  config; against a map ``ncf-map`` and ``salo-map``). The translation error
  is ``|t(T_true^-1 T_est)|``.
- Precision and recall of each rejector against the true correspondences
  (``tools.experiments.truth``) over the nearest-neighbour candidates (no
  search bound) that pass the ICP's plane gate (``odometry.icp.plane_matches``:
  a map point without a usable plane is no candidate; it passes every point
  of a scan target): at the true pose, at each level's initial guess and at
  the ICP's final estimate. Precision = kept true / kept; recall = kept true /
  true candidates; pooled over pairs (sums, not means of ratios). Two
  pseudo-rejectors are counted beside them: "plane_gate" (what the gate keeps
  of every nearest neighbour) and "gcr_unbounded" (candidates whose source has
  no finite threshold, which GCR keeps without judging them).

Reading the target question off it: GCR's threshold is about the sensor's
sampling spacing on the surface (a few cm at 20 m). A true match is only as
close as the target's sampling allows: raw returns are that dense, voxel
centroids are about a voxel apart. GCR's recall at the true pose against each
target, and the distances of true matches set beside the thresholds
(``match_distances.png``), say which target GCR needs.

Measured (``salo experiment rejectors``: 100 pairs of the table's three city
sequences, salo32, 2 cm range noise, seed 0). At the true pose GCR keeps
98.1 % of the true correspondences against the raw previous scan and 92.2 %
against its filtered subset (45-70 deg incidence: 97.8 % against 83.5 %), at
the distance rejector's precision (0.954 / 0.941 against 0.952 / 0.937): true
matches lie a median 7.7 cm from the nearest raw return but 12.0 cm from the
nearest voxel centroid, against thresholds of a median 31 cm here (the rings
are 0.26 deg apart: 9 cm at 20 m head-on, more at oblique incidence). GCR
therefore needs the raw scan as its target. From perturbed guesses its recall
falls much faster than the distance rejector's (3 deg / 0.3 m: 0.45 raw,
0.37 filtered, against 0.80 / 0.77) and ICP with GCR recovers less often
(5 deg / 0.5 m: 80 % of the pairs within 5 cm, against 99-100 %) on either
target: on this data GCR does not beat the distance rejector at any level,
unlike the paper's Fig. 3.

Against a map (``salo experiment rejectors --pairs 20 --targets
filtered,raw,map``, the same sequences, 10 scans in the map): the threshold is
the same sensor spacing, now on the map's normals (on the same source points a
median 32.4 cm, 31.7 cm with the scan's own), but a true match lies a median
7.5-9.6 cm from the nearest map point at every range (the map's voxels set its
spacing), where from the raw previous scan it grows from 2.4 cm within 10 m to
15.8 cm beyond 80 m. With the threshold growing with range (9.6 cm within
10 m, 57 cm beyond 80 m) GCR keeps 63 % of the true map matches within 10 m,
73 % at 10-20 m and 99 % beyond 40 m: 0.918 recall at 0.967 precision in all
(distance rejector 0.993 / 0.967). From perturbed guesses many map sources
have no threshold at all (no plane match within 1 m at the first iteration: 14 %
of the candidates at 3 deg / 0.3 m, 55 % at 10 deg / 1 m), which GCR keeps
unjudged; ICP with GCR against the map ends within 5 cm in 95 % of the pairs at
5 deg / 0.5 m and 10 deg / 1 m, the distance rejector in 100 %.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from simlidar import se3
from tools.records import RunRecord, fmt, markdown_table, write_csv, write_json
from tools.sequence_cache import DEFAULT_CACHE_LIMIT_BYTES, SequenceSpec, load_sequence, table_suite

from .levels import bounded_recall, level_label
from .map_target import MapFrame, build_map_target
from .truth import PointTruth, TruthCriteria, true_matches, truth_of_points, truth_of_rows

log = logging.getLogger(__name__)

DEFAULT_LEVELS = ((0.0, 0.0), (1.0, 0.1), (3.0, 0.3), (5.0, 0.5), (10.0, 1.0))
REJECTORS = ("distance", "gcr")
TARGETS = ("filtered", "raw", "map")
# Incidence angle bins (beam against the true surface normal, deg; 90 = grazing) of the GCR breakdown.
INCIDENCE_BINS_DEG = ((0.0, 45.0), (45.0, 70.0), (70.0, 80.0), (80.0, 85.0), (85.0, 90.01))
# Range bins (source point's distance from its sensor, m) of the GCR breakdown.
RANGE_BINS_M = ((0.0, 10.0), (10.0, 20.0), (20.0, 40.0), (40.0, 80.0), (80.0, math.inf))
# A range bin is quoted in the summary's sentences when it holds this many sampled true matches for every target.
MIN_BIN_SAMPLES = 50
# True matches whose distance is stored per pair for the histogram (a subsample keeps files small).
_DISTANCE_SAMPLES_PER_PAIR = 1500


@dataclass(frozen=True)
class RejectorStudyParams:
    """Sizes and seeds of the study.

    pairs: scan pairs (the paper: 100). levels: (l_r deg, l_t m) noise limits.
    targets: any of "filtered", "raw" (the previous scan) and "map" (a local map of
    the ``map_frames`` scans before the source, ``map_target``). sequences: where the
    pairs come from. seed: the pair draw and the noise draws. truth_sigmas, truth_normal_deg:
    the definition of a true correspondence (``truth.TruthCriteria``).
    config_overrides: changes to the odometry configs (both rejectors), nested by stage as in YAML.
    """

    pairs: int = 100
    levels: tuple[tuple[float, float], ...] = DEFAULT_LEVELS
    targets: tuple[str, ...] = TARGETS
    sequences: tuple[SequenceSpec, ...] = field(
        default_factory=lambda: tuple(s for s in table_suite() if s.scene == "city"))
    seed: int = 0
    truth_sigmas: float = 3.0
    truth_normal_deg: float = 15.0
    config_overrides: dict = field(default_factory=dict)
    map_frames: int = 10

    def to_dict(self) -> dict:
        return {
            "pairs": self.pairs,
            "levels": [{"l_r_deg": r, "l_t_m": t} for r, t in self.levels],
            "targets": list(self.targets),
            "sequences": [s.to_dict() for s in self.sequences],
            "seed": self.seed,
            "truth_sigmas": self.truth_sigmas,
            "truth_normal_deg": self.truth_normal_deg,
            "config_overrides": dict(self.config_overrides),
            "map_frames": self.map_frames,
        }


# ---------------------------------------------------------------- noise
def random_unit_vector(rng: np.random.Generator) -> np.ndarray:
    """(3,) uniform on the unit sphere."""
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def noise_transform(rng: np.random.Generator, l_r_deg: float, l_t_m: float) -> tuple[np.ndarray, float, float]:
    """The paper's perturbation: (4, 4) transform, its angle (deg) and its length (m)."""
    axis_r, axis_t = random_unit_vector(rng), random_unit_vector(rng)
    m_r = rng.uniform(-l_r_deg, l_r_deg) if l_r_deg > 0 else 0.0
    m_t = rng.uniform(-l_t_m, l_t_m) if l_t_m > 0 else 0.0
    xi = np.concatenate([m_t * axis_t, math.radians(m_r) * axis_r])
    # exp of (rho, omega) is not "rotate, then translate by rho": build the two parts directly.
    T = se3.make(se3.exp(np.concatenate([np.zeros(3), xi[3:]]))[:3, :3], xi[:3])
    return T, m_r, m_t


def pose_errors(T_true: np.ndarray, T_est: np.ndarray) -> tuple[float, float]:
    """Translation (m) and rotation (deg) of ``T_true^-1 T_est``."""
    E = se3.inverse(T_true) @ T_est
    return float(np.linalg.norm(E[:3, 3])), float(np.degrees(se3.rotation_angle(E)))


# ---------------------------------------------------------------- scans
@dataclass
class PreparedScan:
    """One frame made ready as the odometry would, plus its truth.

    raw_points: (N', 3) de-skewed in-range returns, sweep-start frame, m.
    raw_rows: (N',) their sidecar rows. filtered: ``odometry.filters.FilteredScan``.
    truth: ``PointTruth`` of the filtered points. truth_tree: k-d tree over ``raw_points``
    (the anchors of the truth). sidecar: the frame's record.
    """

    frame_index: int
    raw_points: np.ndarray
    raw_rows: np.ndarray
    filtered: object
    truth: PointTruth
    truth_tree: object
    sidecar: np.ndarray


def true_motion(poses: np.ndarray, k: int) -> np.ndarray:
    """(4, 4) motion over frame k (pose of the next sweep start in this one's frame)."""
    j = min(k, len(poses) - 2)
    return se3.inverse(poses[j]) @ poses[j + 1]


def prepare_scan(sequence, k: int, config, sensor) -> PreparedScan:
    """Clean, de-skew (true motion) and filter frame k of a simulated sequence, with the odometry's stages.

    With a map-target config the filtered points are the voxel centroids, without normals
    (``odometry.filters.scan_normals_needed``), as the odometry makes them.
    """
    from odometry.deskew import deskew
    from odometry.filters import filter_scan
    from odometry.kdtree import KDTree
    from odometry.preparation import clean_scan

    frame = sequence[k]
    clean = clean_scan(frame.points, frame.time_s, frame.ring, config)
    rows = clean.kept_rows
    times = clean.times_s
    period = float(np.diff(sequence.times[:2])[0]) if len(sequence.times) > 1 else sensor.sweep_period_s
    raw = deskew(clean.points, times, true_motion(sequence.poses, k), period)
    scan = filter_scan(raw, config, clean.rings, sensor, raw_times_s=times)
    tree = scan.raw_tree if scan.raw_tree is not None else KDTree(raw)
    truth = truth_of_points(scan.points, tree, rows, frame.fields)
    return PreparedScan(k, raw, rows, scan, truth, tree, frame.fields)


def make_source(scan: PreparedScan, config, sensor):
    """``odometry.icp.Source`` with GCR thresholds (inf where no neighbour beam bounds them): the odometry's own.

    For a map-target config the scan has no normals: the source then carries the odometry's
    recipe for its thresholds, which ``register`` fills from the map's normals at the first matches.
    """
    from odometry.targets import make_source as odometry_source

    return odometry_source(scan.filtered, config, sensor, with_gcr=True)


def make_target(scan: PreparedScan, kind: str, config):
    """``odometry.icp.Target`` and its ``PointTruth``: the filtered scan, as the odometry builds it, or the raw
    one (normals on demand; ``odometry.targets``)."""
    from odometry.targets import filtered_scan_target, raw_scan_target

    target = (filtered_scan_target(scan.filtered) if kind == "filtered"
              else raw_scan_target(scan.filtered, config.filter.normal_neighbours))
    return target, (scan.truth if kind == "filtered" else truth_of_rows(scan.sidecar, scan.raw_rows))


def map_frame(scan: PreparedScan, T_world_scan: np.ndarray) -> MapFrame:
    """A prepared scan as the map takes it: its voxel centroids with their truth, and its true pose (4, 4)."""
    f = scan.filtered
    truth = scan.truth if f.points is f.centroids else truth_of_points(f.centroids, scan.truth_tree, scan.raw_rows,
                                                                       scan.sidecar)
    return MapFrame(f, truth, T_world_scan)


def same_points(points: np.ndarray, others: np.ndarray) -> np.ndarray:
    """(M,) bool: which of the (M, 3) ``points`` are also among the (K, 3) ``others`` (within 1 nm).

    The scan-to-scan source's points are voxel centroids of the same de-skewed scan on the
    same grid as the map source's, so the shared ones coincide to the last bit.
    """
    from scipy.spatial import cKDTree

    if len(others) == 0:
        return np.zeros(len(points), dtype=bool)
    d, _ = cKDTree(others).query(points, k=1, distance_upper_bound=1e-9)
    return np.isfinite(d)


@dataclass
class TargetCase:
    """One source scan and one target kind, with what registering and judging them needs.

    kind: "filtered", "raw" or "map". source: ``odometry.icp.Source`` as the odometry makes it
    for this target (against a map: no thresholds until the first matches give them).
    source_truth: ``PointTruth`` of its points, their own frame. target, target_truth: the
    target and the truth of its points, in the target's frame (the previous scan's, or the
    world for a map). T_true: (4, 4) the source's true pose in the target's frame.
    T_previous: (4, 4) the previous sensor pose there (``register``'s ``T_target_previous``;
    None: the origin, the target scan's own sensor). configs: {"distance", "gcr"}: the
    odometry configs of the two rejection chains. in_scan_source: (M,) bool, which source
    points are also points of the scan-to-scan source (the ones the scan's filters keep; all
    of them for a scan target), or None when that source was not made.
    """

    kind: str
    source: object
    source_truth: PointTruth
    target: object
    target_truth: PointTruth
    T_true: np.ndarray
    T_previous: np.ndarray | None
    configs: dict
    in_scan_source: np.ndarray | None = None

    @property
    def centre(self) -> np.ndarray:
        """(3,) the previous sensor position in the target's frame, m (the ICP linearises about it)."""
        return np.zeros(3) if self.T_previous is None else np.asarray(self.T_previous[:3, 3], dtype=float)

    def fresh_source(self):
        """The source for one registration: against a map a copy without thresholds (``register``
        sets them from its own first matches); against a scan the shared one (fixed thresholds)."""
        if self.source.gcr_thresholds is None:
            return self.source
        return dataclasses.replace(self.source, gcr_threshold_m=None)

    def source_from(self, T: np.ndarray):
        """The source with the GCR thresholds an ICP starting at ``T`` (4, 4) uses: against a map,
        those ``register``'s first iteration sets from the map's normals at its matches (that
        iteration is run for it, with the GCR chain's config)."""
        from odometry.icp import register

        src = self.fresh_source()
        if src.gcr_threshold_m is None:
            register(src, self.target, T, self.configs["gcr"].replace(icp={"max_iterations": 1}), [], self.T_previous)
        return src


def evaluation_chains(configs: dict) -> dict:
    """The rejectors judged against the truth: each alone, and the two chains the ICP runs."""
    from odometry.icp import rejectors_for
    from odometry.rejectors import distance_rejector, geometric_rejector, trimmed_rejector

    base = configs["distance"]
    return {
        "distance": [distance_rejector(base.match.max_correspondence_distance_m)],
        "gcr": [geometric_rejector()],
        "trimmed": [trimmed_rejector(base.match.trim_fraction)],
        "bl_chain": rejectors_for(configs["distance"]),
        "salo_chain": rejectors_for(configs["gcr"]),
    }


# ---------------------------------------------------------------- rejection against the truth
def chain_keep(matches, source, chain) -> np.ndarray:
    """(m,) bool over ``matches``: what a rejector chain keeps, applied in order as the ICP does."""
    idx = np.arange(len(matches))
    cur = matches
    for reject in chain:
        keep = reject(cur, source)
        idx, cur = idx[keep], cur.select(keep)
    mask = np.zeros(len(matches), dtype=bool)
    mask[idx] = True
    return mask


def rejection_counts(case: TargetCase, source, T: np.ndarray, criteria: TruthCriteria, chains: dict
                     ) -> tuple[dict, dict]:
    """Counts per chain over the unbounded nearest-neighbour candidates at pose T (4, 4).

    The candidates are those the rejectors would see: matches to target points without
    a plane (or, on a map, with an NCF-uncertain normal) are first dropped as the ICP
    drops them (``odometry.icp.plane_matches``; a scan target with fixed normals keeps
    all); that gate is counted as "plane_gate" over every nearest neighbour. And
    "gcr_unbounded" counts as "kept" the candidates whose source point has no finite
    GCR threshold (grazing incidence; against a map also no plane match within the
    distance bound at the first iteration): GCR keeps those without judging them.

    Returns ({chain: {candidates, true, kept, kept_true}}, and for the t true
    candidates a dict of (t,) arrays: "distance_m" (match distance),
    "gcr_threshold_m" (their source point's threshold), "incidence_deg" (angle
    between the source point's beam and its true surface normal, 90 = grazing),
    "range_m" (the source point's distance from its sensor), "scan_source" (the
    source point is one the scan-to-scan source has too: 1, 0, or nan when unknown)).
    """
    from odometry.icp import plane_matches
    from odometry.rejectors import Matches

    moved = se3.transform_points(T, source.points)
    dist, idx = case.target.tree.query(moved, k=1)
    every = Matches(np.arange(len(moved)), np.asarray(idx), np.asarray(dist))
    m, _ = plane_matches(every, case.target, moved, case.centre, case.configs["gcr"])

    def truth_of(matches):
        return true_matches(case.source_truth, case.target_truth, matches.source_index, matches.target_index,
                            case.T_true, criteria)

    is_true = truth_of(m)
    counts = {"plane_gate": {"candidates": len(every), "true": int(truth_of(every).sum()), "kept": len(m),
                             "kept_true": int(is_true.sum())}}
    for name, chain in chains.items():
        keep = chain_keep(m, source, chain)
        counts[name] = {"candidates": len(m), "true": int(is_true.sum()), "kept": int(keep.sum()),
                        "kept_true": int((keep & is_true).sum())}
    if source.gcr_threshold_m is not None:
        unbounded = ~np.isfinite(source.gcr_threshold_m[m.source_index])
        counts["gcr_unbounded"] = {"candidates": len(m), "true": int(is_true.sum()), "kept": int(unbounded.sum()),
                                   "kept_true": int((unbounded & is_true).sum())}
    src = m.source_index[is_true]
    ranges = np.linalg.norm(source.points[src], axis=1)
    beam = source.points[src] / ranges[:, None]
    cos_inc = np.abs(np.einsum("ij,ij->i", beam, case.source_truth.normal[src]))
    true_stats = {"distance_m": m.distance_m[is_true], "gcr_threshold_m": source.gcr_threshold_m[src],
                  "incidence_deg": np.degrees(np.arccos(np.clip(cos_inc, 0.0, 1.0))), "range_m": ranges,
                  "scan_source": (np.full(len(src), np.nan) if case.in_scan_source is None
                                  else case.in_scan_source[src].astype(float))}
    return counts, true_stats


def _ratio(a: float, b: float) -> float:
    return a / b if b > 0 else float("nan")


# ---------------------------------------------------------------- the study
@dataclass
class RejectorStudyResult:
    """Per-registration rows, per-evaluation precision/recall rows, summaries and distance samples."""

    registrations: list[dict]
    rejection: list[dict]
    error_summary: list[dict]
    pr_summary: list[dict]
    distance_samples: dict
    pairs: list[dict]
    finding: dict


def draw_pairs(lengths: list[int], n: int, rng: np.random.Generator) -> list[tuple[int, int]]:
    """``n`` distinct (sequence, source frame) pairs from sequences of ``lengths`` frames, sorted."""
    all_pairs = [(s, k) for s, length in enumerate(lengths) for k in range(1, length)]
    if n >= len(all_pairs):
        return all_pairs
    pick = rng.choice(len(all_pairs), size=n, replace=False)
    return sorted(all_pairs[i] for i in pick)


def run_rejector_study(params: RejectorStudyParams, cache_dir: str | Path | None, progress: bool = False,
                       cache_limit_bytes: int | None = DEFAULT_CACHE_LIMIT_BYTES) -> RejectorStudyResult:
    """Run the study (see the module notes); nothing is written (``write_rejector_study`` does)."""
    from tqdm import tqdm

    from odometry.config import variant
    from odometry.icp import register

    unknown = sorted(set(params.targets) - set(TARGETS))
    if unknown:
        raise ValueError(f"unknown target {unknown[0]!r} (known: {', '.join(TARGETS)})")
    if params.map_frames < 1:
        raise ValueError(f"map_frames must be >= 1, got {params.map_frames}")
    overrides = dict(params.config_overrides)
    scan_configs = {"distance": variant("ncf").replace(**overrides), "gcr": variant("salo").replace(**overrides)}
    # The odometry's map variants: NCF on the map's normals, so the scan has none of its own and
    # the GCR thresholds come from the map's normals at the first matches.
    on_map = {**overrides, "match": {**overrides.get("match", {}), "target": "map"}}
    map_configs = {"distance": variant("ncf-map").replace(**on_map), "gcr": variant("salo-map").replace(**on_map)}
    # cache_dir None: simulated in memory, with the per-point truth the study judges against
    sequences = [load_sequence(s, cache_dir, progress, fields="truth", cache_limit_bytes=cache_limit_bytes)
                 for s in params.sequences]
    rng = np.random.default_rng([params.seed, 0x5EED])
    chosen = draw_pairs([len(s) for s in sequences], params.pairs, rng)
    regs, rej, pair_rows = [], [], []
    samples = {t: {"distance_m": [], "gcr_threshold_m": [], "incidence_deg": [], "range_m": [], "scan_source": []}
               for t in params.targets}
    prepared_map: dict[tuple[int, int], MapFrame] = {}  # prepared map scans, reused by nearby pairs
    for p_idx, (s_idx, k) in enumerate(tqdm(chosen, desc="rejector study", unit="pair", disable=not progress,
                                            dynamic_ncols=True)):
        seq, spec = sequences[s_idx], params.sequences[s_idx]
        sensor = seq.sensor
        criteria = TruthCriteria.for_noise(sensor.range_noise_std_m, params.truth_sigmas, params.truth_normal_deg)
        T_true = se3.inverse(seq.poses[k - 1]) @ seq.poses[k]
        pair = {"pair": p_idx, "sequence": spec.name, "target_frame": k - 1, "source_frame": k,
                "source_points": None, "target_filtered_points": None, "target_raw_points": None,
                "map_frames": None, "map_points": None, "map_source_points": None,
                "motion_m": float(np.linalg.norm(T_true[:3, 3]))}
        cases, source = [], None
        if {"filtered", "raw"} & set(params.targets):
            tgt_scan = prepare_scan(seq, k - 1, scan_configs["gcr"], sensor)
            src_scan = prepare_scan(seq, k, scan_configs["gcr"], sensor)
            source = make_source(src_scan, scan_configs["gcr"], sensor)
            pair.update(source_points=len(source.points), target_filtered_points=len(tgt_scan.filtered),
                        target_raw_points=len(tgt_scan.raw_points))
            for kind in ("filtered", "raw"):
                if kind in params.targets:
                    target, tgt_truth = make_target(tgt_scan, kind, scan_configs["gcr"])
                    cases.append(TargetCase(kind, source, src_scan.truth, target, tgt_truth, T_true, None,
                                            scan_configs, np.ones(len(source.points), dtype=bool)))
        if "map" in params.targets:
            first = max(0, k - params.map_frames)
            for key in [key for key in prepared_map if key[0] != s_idx or key[1] < first]:
                del prepared_map[key]
            for j in range(first, k):
                if (s_idx, j) not in prepared_map:
                    prepared_map[(s_idx, j)] = map_frame(prepare_scan(seq, j, map_configs["gcr"], sensor),
                                                         seq.poses[j])
            built = build_map_target([prepared_map[(s_idx, j)] for j in range(first, k)], map_configs["gcr"],
                                     sensor)
            src_map = prepare_scan(seq, k, map_configs["gcr"], sensor)
            prepared_map[(s_idx, k)] = map_frame(src_map, seq.poses[k])  # the next pair's map may hold it
            map_source = make_source(src_map, map_configs["gcr"], sensor)
            pair.update(map_frames=built.frames, map_points=len(built.target.points),
                        map_source_points=len(map_source.points))
            cases.append(TargetCase("map", map_source, src_map.truth, built.target, built.truth, seq.poses[k],
                                    seq.poses[k - 1], map_configs,
                                    None if source is None else same_points(map_source.points, source.points)))
        cases.sort(key=lambda c: params.targets.index(c.kind))
        pair_rows.append(pair)
        # One perturbation per pair and level, shared by every target and rejector: the guess is
        # T_true @ T_noise in each target's frame (the same error in the source's frame).
        noises = [noise_transform(np.random.default_rng([params.seed, p_idx, l_idx]), l_r, l_t)
                  for l_idx, (l_r, l_t) in enumerate(params.levels)]
        for case in cases:
            kind = case.kind
            chains = evaluation_chains(case.configs)
            common = {"pair": p_idx, "sequence": spec.name, "source_frame": k, "target": kind}
            counts, true_stats = rejection_counts(case, case.source_from(case.T_true), case.T_true, criteria, chains)
            n_true = len(true_stats["distance_m"])
            take = np.random.default_rng([params.seed, p_idx, 7]).permutation(n_true)[:_DISTANCE_SAMPLES_PER_PAIR]
            for key, values in true_stats.items():
                samples[kind][key].extend(values[take].tolist())
            for chain, c in counts.items():
                rej.append({**common, "stage": "true pose", "level": "true pose", "l_r_deg": None, "l_t_m": None,
                            "rejector": chain, **c})
            for (l_r, l_t), (T_noise, m_r, m_t) in zip(params.levels, noises, strict=True):
                level = level_label((l_r, l_t))
                T_init = case.T_true @ T_noise
                init_t, init_r = pose_errors(case.T_true, T_init)
                counts, _ = rejection_counts(case, case.source_from(T_init), T_init, criteria, chains)
                for chain, c in counts.items():
                    rej.append({**common, "stage": "initial guess", "level": level, "l_r_deg": l_r, "l_t_m": l_t,
                                "rejector": chain, **c})
                for name in REJECTORS:
                    source = case.fresh_source()  # (against a map: thresholds from this run's first matches)
                    res = register(source, case.target, T_init, case.configs[name], None, case.T_previous)
                    t_err, r_err = pose_errors(case.T_true, res.T_target_source)
                    regs.append({**common, "level": level, "l_r_deg": l_r, "l_t_m": l_t, "m_r_deg": m_r,
                                 "m_t_m": m_t, "rejector": name, "initial_t_err_m": init_t,
                                 "initial_r_err_deg": init_r, "t_err_m": t_err, "r_err_deg": r_err,
                                 "iterations": res.iterations, "converged": res.converged,
                                 "singular": res.singular, "matches": res.n_matches})
                    chain = "bl_chain" if name == "distance" else "salo_chain"
                    c_fin, _ = rejection_counts(case, source, res.T_target_source, criteria, {chain: chains[chain]})
                    rej.append({**common, "stage": "final estimate", "level": level, "l_r_deg": l_r, "l_t_m": l_t,
                                "rejector": chain, **c_fin[chain]})
    err_summary = summarize_errors(regs, params)
    pr_summary = summarize_rejection(rej)
    return RejectorStudyResult(regs, rej, err_summary, pr_summary, samples, pair_rows,
                               target_finding(pr_summary, samples, params.targets, pair_rows))


def summarize_errors(regs: list[dict], params: RejectorStudyParams) -> list[dict]:
    """Per (level, target, rejector): count, median / mean / p90 translation error, recovered share."""
    out = []
    for level in params.levels:
        label = level_label(level)
        for kind in params.targets:
            for name in REJECTORS:
                rows = [r for r in regs if r["level"] == label and r["target"] == kind and r["rejector"] == name]
                if not rows:
                    continue
                t = np.array([r["t_err_m"] for r in rows])
                rr = np.array([r["r_err_deg"] for r in rows])
                out.append({
                    "level": label, "l_r_deg": level[0], "l_t_m": level[1], "target": kind, "rejector": name,
                    "count": len(rows), "t_err_median_m": float(np.median(t)), "t_err_mean_m": float(np.mean(t)),
                    "t_err_p90_m": float(np.percentile(t, 90)), "t_err_max_m": float(np.max(t)),
                    "r_err_median_deg": float(np.median(rr)),
                    "recovered_5cm": float(np.mean(t < 0.05)),
                    "iterations_median": float(np.median([r["iterations"] for r in rows])),
                    "singular": int(sum(r["singular"] for r in rows)),
                })
    return out


def summarize_rejection(rej: list[dict]) -> list[dict]:
    """Pooled precision and recall per (stage, level, target, rejector)."""
    groups: dict[tuple, dict] = {}
    for r in rej:
        key = (r["stage"], r["level"], r["target"], r["rejector"])
        g = groups.setdefault(key, {"candidates": 0, "true": 0, "kept": 0, "kept_true": 0, "evaluations": 0})
        for c in ("candidates", "true", "kept", "kept_true"):
            g[c] += r[c]
        g["evaluations"] += 1
    out = []
    for (stage, level, target, rejector), g in groups.items():
        out.append({"stage": stage, "level": level, "target": target, "rejector": rejector, **g,
                    "true_fraction": _ratio(g["true"], g["candidates"]),
                    "precision": _ratio(g["kept_true"], g["kept"]), "recall": _ratio(g["kept_true"], g["true"]),
                    "kept_fraction": _ratio(g["kept"], g["candidates"])})
    return out


def _median_of(rows: list[dict], key: str) -> float | None:
    values = [r[key] for r in rows if r.get(key) is not None]
    return float(np.median(values)) if values else None


def _binned(d: np.ndarray, thr: np.ndarray, sel: np.ndarray) -> dict:
    """Sampled true matches in a bin: count, GCR's recall, median distance and threshold (m)."""
    return {"true_matches_sampled": int(sel.sum()),
            "gcr_recall": float(np.mean(d[sel] < thr[sel])) if sel.any() else None,
            "distance_median_m": float(np.median(d[sel])) if sel.any() else None,
            "gcr_threshold_median_m": float(np.median(thr[sel])) if sel.any() else None}


def target_finding(pr_summary: list[dict], samples: dict, targets, pairs: list[dict] | None = None) -> dict:
    """Per target: GCR's and the distance rejector's precision / recall at the true pose and at each
    level's initial guess, the plane gate's share, the distances behind them and the targets' sizes."""
    out = {}
    pairs = pairs or []
    for kind in targets:
        row = {r["rejector"]: r for r in pr_summary if r["stage"] == "true pose" and r["target"] == kind}
        gate = row.get("plane_gate")
        at_guess = []
        for r in pr_summary:
            if r["stage"] == "initial guess" and r["target"] == kind and r["rejector"] == "gcr":
                dist = next((d for d in pr_summary if d["stage"] == "initial guess" and d["target"] == kind
                             and d["level"] == r["level"] and d["rejector"] == "distance"), None)
                free = next((d for d in pr_summary if d["stage"] == "initial guess" and d["target"] == kind
                             and d["level"] == r["level"] and d["rejector"] == "gcr_unbounded"), None)
                gated = next((d for d in pr_summary if d["stage"] == "initial guess" and d["target"] == kind
                              and d["level"] == r["level"] and d["rejector"] == "plane_gate"), None)
                at_guess.append({"level": r["level"], "gcr_precision": r["precision"], "gcr_recall": r["recall"],
                                 "distance_precision": dist["precision"] if dist else None,
                                 "distance_recall": dist["recall"] if dist else None,
                                 "gcr_unbounded_fraction": free["kept_fraction"] if free else None,
                                 "gcr_recall_bounded": bounded_recall(r, free),
                                 "plane_gate_kept_fraction": gated["kept_fraction"] if gated else None,
                                 "plane_gate_recall": gated["recall"] if gated else None})
        d = np.asarray(samples[kind]["distance_m"])
        thr = np.asarray(samples[kind]["gcr_threshold_m"])
        inc = np.asarray(samples[kind]["incidence_deg"])
        shared = np.asarray(samples[kind].get("scan_source", np.full(len(d), np.nan))) == 1
        finite = np.isfinite(thr)
        rng_m = np.asarray(samples[kind].get("range_m", np.full(len(d), np.nan)))
        by_incidence = [{"incidence_lo_deg": lo, "incidence_hi_deg": hi, **_binned(d, thr, (inc >= lo) & (inc < hi))}
                        for lo, hi in INCIDENCE_BINS_DEG]
        by_range = [{"range_lo_m": lo, "range_hi_m": hi, **_binned(d, thr, (rng_m >= lo) & (rng_m < hi))}
                    for lo, hi in RANGE_BINS_M]
        out[kind] = {
            "gcr_precision": row["gcr"]["precision"] if "gcr" in row else None,
            "gcr_recall": row["gcr"]["recall"] if "gcr" in row else None,
            "distance_precision": row["distance"]["precision"] if "distance" in row else None,
            "distance_recall": row["distance"]["recall"] if "distance" in row else None,
            "true_fraction": row["gcr"]["true_fraction"] if "gcr" in row else None,
            "true_match_distance_median_m": float(np.median(d)) if len(d) else None,
            "gcr_threshold_median_m": float(np.median(thr[finite])) if finite.any() else None,
            "gcr_recall_sampled": float(np.mean(d < thr)) if len(d) else None,
            # the same statistics over the sources the scan-to-scan source has too (like for like)
            "scan_source_points": {
                "true_matches_sampled": int(shared.sum()),
                "distance_median_m": float(np.median(d[shared])) if shared.any() else None,
                "gcr_threshold_median_m": (float(np.median(thr[shared & finite])) if (shared & finite).any()
                                           else None),
                "gcr_recall": float(np.mean(d[shared] < thr[shared])) if shared.any() else None,
            },
            "plane_gate_kept_fraction": gate["kept_fraction"] if gate else None,
            "plane_gate_recall": gate["recall"] if gate else None,
            "gcr_unbounded_fraction": row["gcr_unbounded"]["kept_fraction"] if "gcr_unbounded" in row else None,
            "gcr_recall_bounded": bounded_recall(row["gcr"], row.get("gcr_unbounded")) if "gcr" in row else None,
            "source_points_median": _median_of(pairs, "map_source_points" if kind == "map" else "source_points"),
            "target_points_median": _median_of(pairs, {"filtered": "target_filtered_points",
                                                       "raw": "target_raw_points", "map": "map_points"}[kind]),
            "map_frames_median": _median_of(pairs, "map_frames") if kind == "map" else None,
            "initial_guess": at_guess,
            "by_incidence": by_incidence,
            "by_range": by_range,
        }
    return out


# ---------------------------------------------------------------- files
def write_rejector_study(result: RejectorStudyResult, record: RunRecord) -> None:
    """results.json, CSV tables, summary.md and the figures into the run folder."""
    from . import plots

    reg_cols = ["pair", "sequence", "source_frame", "target", "level", "l_r_deg", "l_t_m", "m_r_deg", "m_t_m",
                "rejector", "initial_t_err_m", "initial_r_err_deg", "t_err_m", "r_err_deg", "iterations",
                "converged", "singular", "matches"]
    write_csv(record.path("registrations.csv"), result.registrations, reg_cols)
    write_csv(record.path("rejection.csv"), result.rejection,
              ["pair", "sequence", "source_frame", "target", "stage", "level", "l_r_deg", "l_t_m", "rejector",
               "candidates", "true", "kept", "kept_true"])
    write_csv(record.path("pairs.csv"), result.pairs, list(result.pairs[0]) if result.pairs else ["pair"])
    write_csv(record.path("translation_error_summary.csv"), result.error_summary,
              list(result.error_summary[0]) if result.error_summary else ["level"])
    write_csv(record.path("precision_recall.csv"), result.pr_summary,
              list(result.pr_summary[0]) if result.pr_summary else ["stage"])
    write_json(record.path("results.json"), {
        "experiment": "rejectors", "params": record.params, "finding": result.finding,
        "translation_error": result.error_summary, "precision_recall": result.pr_summary, "pairs": result.pairs})
    figs = {
        "translation_error_boxplot.png": lambda p: plots.rejector_boxplot(p, result.registrations, record.params),
        "precision_recall.png": lambda p: plots.rejector_precision_recall(p, result.pr_summary, record.params),
        "match_distances.png": lambda p: plots.match_distance_histogram(p, result.distance_samples),
    }
    for name, draw in figs.items():
        draw(record.path(name))
    record.write_text("summary.md", rejector_markdown(record.params, result.error_summary, result.pr_summary,
                                                           result.finding, len(result.pairs)))


def verdict_lines(error_summary: list[dict], finding: dict) -> tuple[list[str], list[str]]:
    """Bullets stating what the figures say: (GCR's recall per target, GCR against distance per level)."""
    out, levels = [], []
    if {"filtered", "raw"} <= set(finding):
        f, r = finding["filtered"], finding["raw"]
        if f["gcr_recall"] is not None and r["gcr_recall"] is not None:
            better = "raw" if r["gcr_recall"] > f["gcr_recall"] else "filtered"
            out.append(f"At the true pose GCR keeps {100 * r['gcr_recall']:.1f} % of the true correspondences "
                       f"against the raw target and {100 * f['gcr_recall']:.1f} % against the filtered one "
                       f"(precision {r['gcr_precision']:.3f} / {f['gcr_precision']:.3f}; the distance rejector's "
                       f"{r['distance_precision']:.3f} / {f['distance_precision']:.3f}): GCR keeps more true "
                       f"matches against the {better} target.")
    if "map" in finding and finding["map"]["gcr_recall"] is not None:
        m = finding["map"]
        out.append(f"At the true pose GCR keeps {100 * m['gcr_recall']:.1f} % of the true correspondences against "
                   f"the map (precision {m['gcr_precision']:.3f}; the distance rejector's "
                   f"{fmt(m['distance_precision'], '.3f')}, recall {fmt(m['distance_recall'], '.3f')}), among the "
                   f"matches the ICP's plane gate passes: it drops those to map points without a usable plane, "
                   f"{_pct(1 - m['plane_gate_kept_fraction'])} % of the candidates and "
                   f"{_pct(1 - m['plane_gate_recall'])} % of the true ones.")
    for row in error_summary:
        if row["rejector"] != "gcr":
            continue
        dist = next((d for d in error_summary if d["rejector"] == "distance" and d["level"] == row["level"]
                     and d["target"] == row["target"]), None)
        if dist is not None and row["recovered_5cm"] < dist["recovered_5cm"]:
            levels.append(f"At {row['level']} ({row['target']} target) ICP with GCR ends within 5 cm of the truth in "
                       f"{100 * row['recovered_5cm']:.0f} % of the pairs, with the distance rejector in "
                       f"{100 * dist['recovered_5cm']:.0f} %: here GCR does worse than the baseline.")
    return ([f"- {t}" for t in out] + ([""] if out else []),
            [f"- {t}" for t in levels] + ([""] if levels else []))


def _range_label(b: dict) -> str:
    hi = b["range_hi_m"]
    return f"{b['range_lo_m']:g}+" if hi is None or not math.isfinite(hi) else f"{b['range_lo_m']:g}-{hi:g}"


def _pct(x: float | None) -> str:
    return fmt(None if x is None else 100 * x, ".1f")


def _cm(x: float | None) -> str:
    return fmt(None if x is None else 100 * x, ".1f")


def map_threshold_lines(finding: dict, params: dict) -> list[str]:
    """The measured meaning of GCR's threshold against a map (bullets and a table), from the finding."""
    m = finding["map"]
    scans = [(k, finding[k]) for k in ("filtered", "raw") if k in finding]
    shared = m.get("scan_source_points") or {}
    out = [f"GCR's threshold max d_kl is the spacing of the source sensor's own sampling on the surface (where "
           f"its neighbour beams hit it), whatever the target. Against a map the scan has no normals: the "
           f"surface is the map's plane at each point's first match, turned into the scan's frame. At the true "
           f"pose the thresholds are a median {_cm(m['gcr_threshold_median_m'])} cm over the map source's true "
           f"matches (every voxel centroid of the scan)."]
    if shared.get("true_matches_sampled") and scans:
        f0 = scans[0][1]
        out.append(f"Like for like, on the source points the scan-to-scan source has too (those the scan's NCF and "
                   f"curvature filters keep; {shared['true_matches_sampled']} sampled true matches): thresholds "
                   f"a median {_cm(shared['gcr_threshold_median_m'])} cm from the map's normals against "
                   f"{_cm(f0['gcr_threshold_median_m'])} cm from the scan's own, and true matches a median "
                   f"{_cm(shared['distance_median_m'])} cm from their nearest map point against "
                   + " and ".join(f"{_cm(f['true_match_distance_median_m'])} cm from the nearest point of the {k} "
                                  f"previous scan" for k, f in scans)
                   + f"; GCR keeps {_pct(shared['gcr_recall'])} % of them against the map, "
                   + " and ".join(f"{_pct(f['gcr_recall_sampled'])} % against the {k} scan" for k, f in scans)
                   + " (sampled true matches).")
    others = [(k, f) for k, f in scans if f.get("by_range")]
    ranges = [i for i, b in enumerate(m.get("by_range", []))
              if min([b["true_matches_sampled"]] + [f["by_range"][i]["true_matches_sampled"] for _, f in others])
              >= MIN_BIN_SAMPLES]
    if ranges:
        def row(f: dict, key: str, as_text) -> str:
            return " / ".join(as_text(f["by_range"][i][key]) for i in ranges)

        out.append(f"By the source point's range ({' / '.join(_range_label(m['by_range'][i]) for i in ranges)} m): "
                   f"true matches lie a median {row(m, 'distance_median_m', _cm)} cm from their nearest map point"
                   + "".join(f", {row(f, 'distance_median_m', _cm)} cm from the {k} previous scan" for k, f in others)
                   + f"; the map source's thresholds are a median {row(m, 'gcr_threshold_median_m', _cm)} cm, and "
                   f"GCR keeps "
                   f"{row(m, 'gcr_recall', _pct)} % of the true matches against the map"
                   + "".join(f", {row(f, 'gcr_recall', _pct)} % against the {k} scan" for k, f in others) + ".")
    d_map, thr_map = m["true_match_distance_median_m"], m["gcr_threshold_median_m"]
    if d_map:
        text = (f"Over all its sources, true matches lie a median {_cm(d_map)} cm from their nearest map point (a "
                f"median {fmt(m['map_frames_median'], 'g')} earlier scans, {fmt(m['target_points_median'], '.0f')} "
                f"map points; one filtered scan has {fmt(scans[0][1]['target_points_median'], '.0f')} points)"
                if scans else f"Over all its sources, true matches lie a median {_cm(d_map)} cm from their nearest "
                f"map point")
        if thr_map:
            text += f": the median threshold is {thr_map / d_map:.1f} times the median true-match distance"
            ratios = [f"{f['gcr_threshold_median_m'] / f['true_match_distance_median_m']:.1f} against the {k} scan"
                      for k, f in scans if f["gcr_threshold_median_m"] and f["true_match_distance_median_m"]]
            text += f" ({', '.join(ratios)})" if ratios else ""
        out.append(text + ".")
    recall = (f"Pooled over every candidate at the true pose GCR keeps {_pct(m['gcr_recall'])} % of the true "
              f"matches against the map at precision {fmt(m['gcr_precision'], '.3f')}")
    if scans:
        recall += ", against " + " and ".join(f"{_pct(f['gcr_recall'])} % at {fmt(f['gcr_precision'], '.3f')} with "
                                              f"the {k} previous scan" for k, f in scans)
    out.append(recall + ".")
    guesses = [g for g in m["initial_guess"] if g["gcr_unbounded_fraction"]]
    if guesses:
        g = max(guesses, key=lambda g: g["gcr_unbounded_fraction"])
        out.append(f"From a perturbed guess the thresholds come from the map's normals at the matches the wrong pose "
                   f"makes, and a source point with no plane match within the distance bound then has none: GCR "
                   f"keeps it unjudged. At {g['level']} that is {_pct(g['gcr_unbounded_fraction'])} % of the "
                   f"candidates; over those it judges GCR keeps {_pct(g['gcr_recall_bounded'])} % of the true ones "
                   f"({_pct(g['gcr_recall'])} % counting the unjudged; the distance rejector "
                   f"{_pct(g['distance_recall'])} %).")
    lines = [f"- {t}" for t in out] + [""]
    header = ["where", "plane gate keeps", "of the true", "GCR unjudged", "GCR recall", "GCR recall, judged",
              "GCR precision", "distance recall", "distance precision"]
    rows = [["true pose", _pct(m["plane_gate_kept_fraction"]), _pct(m["plane_gate_recall"]),
             _pct(m["gcr_unbounded_fraction"]), fmt(m["gcr_recall"], ".3f"), fmt(m["gcr_recall_bounded"], ".3f"),
             fmt(m["gcr_precision"], ".3f"), fmt(m["distance_recall"], ".3f"), fmt(m["distance_precision"], ".3f")]]
    rows += [[f"guess {g['level']}", _pct(g["plane_gate_kept_fraction"]), _pct(g["plane_gate_recall"]),
              _pct(g["gcr_unbounded_fraction"]), fmt(g["gcr_recall"], ".3f"), fmt(g["gcr_recall_bounded"], ".3f"),
              fmt(g["gcr_precision"], ".3f"), fmt(g["distance_recall"], ".3f"), fmt(g["distance_precision"], ".3f")]
             for g in m["initial_guess"]]
    lines += ["Map target (shares in %; \"unjudged\": candidates whose source has no finite threshold, which GCR "
              "keeps; \"judged\": GCR's recall over the others):", "", markdown_table(header, rows, "lrrrrrrrr"), ""]
    return lines


def rejector_markdown(params: dict, error_summary: list[dict], pr_summary: list[dict], finding: dict,
                      pairs: int) -> str:
    """The study's human-readable page (tables, the target finding, the figures), from what results.json holds."""
    lines = ["# Rejector study: GCR against the distance rejector (SALO Sec. IV-A, Fig. 3)", ""]
    lines.append(f"{pairs} scan pairs from {', '.join(s['name'] for s in params['sequences'])}; "
                 f"initial guess = true pose composed with a random rotation (uniform in [-l_r, l_r] about a random "
                 "axis) and translation (uniform in [-l_t, l_t] along a random axis); seed "
                 f"{params['seed']}. Scans de-skewed with the true motion, filtered as the `salo` config "
                 "(NCF on). \"distance\" = the baseline's chain (distance 1 m, trimming 20 %); \"gcr\" = SALO's "
                 "(distance bound, GCR, trimming).")
    if "map" in params["targets"]:
        lines.append("")
        lines.append(f"The *map* target: the {params.get('map_frames', 10)} scans before the source (fewer at a "
                     "sequence's start) inserted at their true poses into the odometry's local map (world frame, "
                     "1 m voxels of at most 20 points, normals estimated in the map where it is a plane, the map's "
                     "NCF on), registered with the map variants' configs (`ncf-map`, `salo-map`): the source is "
                     "every voxel centroid of the scan, without normals, and its GCR thresholds come from the map's "
                     "normals at each point's first match.")
    lines.append("")
    lines.append("A correspondence is *true* when both points' nearest raw returns hit the same object, their "
                 f"true normals agree within {params['truth_normal_deg']:g} deg, and at the true pose the "
                 f"noise-free point-to-plane residual is below {params['truth_sigmas']:g} range-noise sigmas "
                 "(`tools/experiments/truth.py`).")
    lines += ["", "## Translation error after ICP, m", ""]
    header = ["level (l_r / l_t)", "target", "rejector", "n", "median", "mean", "p90", "max", "< 5 cm",
              "median iterations"]
    rows = [[r["level"], r["target"], r["rejector"], r["count"], fmt(r["t_err_median_m"], ".4f"),
             fmt(r["t_err_mean_m"], ".4f"), fmt(r["t_err_p90_m"], ".4f"), fmt(r["t_err_max_m"], ".3f"),
             f"{100 * r['recovered_5cm']:.0f} %", fmt(r["iterations_median"], ".0f")] for r in error_summary]
    lines.append(markdown_table(header, rows, "lllrrrrrrr"))
    lines += verdict_lines(error_summary, finding)[1]
    lines += ["![translation error per level](translation_error_boxplot.png)", ""]
    lines += ["## Precision and recall against the true correspondences", ""]
    lines.append("Over the nearest-neighbour candidates (no search bound), pooled over pairs. At the *true pose* "
                 "the candidates are what a converged ICP would see; at the *initial guess*, what the first "
                 "iteration sees; at the *final estimate*, the chain the ICP ran with.")
    lines.append("")
    header = ["stage", "level", "target", "rejector", "true share", "kept share", "precision", "recall"]
    order = {"true pose": 0, "initial guess": 1, "final estimate": 2}
    level_order = {"true pose": -1, **{level_label((lv["l_r_deg"], lv["l_t_m"])): i
                                       for i, lv in enumerate(params["levels"])}}
    rows = [[r["stage"], r["level"], r["target"], r["rejector"], fmt(r["true_fraction"], ".3f"),
             fmt(r["kept_fraction"], ".3f"), fmt(r["precision"], ".3f"), fmt(r["recall"], ".3f")]
            for r in sorted(pr_summary, key=lambda r: (order[r["stage"]], level_order.get(r["level"], 99),
                                                        r["target"]))
            if r["rejector"] in ("distance", "gcr", "bl_chain", "salo_chain")]
    lines.append(markdown_table(header, rows, "llllrrrr"))
    lines += ["![precision and recall](precision_recall.png)", ""]
    lines += ["## Which target GCR needs", ""]
    lines += verdict_lines(error_summary, finding)[0]
    for kind, f in finding.items():
        lines.append(f"- **{kind}** target, at the true pose: GCR precision {fmt(f['gcr_precision'], '.3f')}, "
                     f"recall {fmt(f['gcr_recall'], '.3f')} (distance rejector: precision "
                     f"{fmt(f['distance_precision'], '.3f')}, recall {fmt(f['distance_recall'], '.3f')}); "
                     f"true matches lie a median {fmt(f['true_match_distance_median_m'], '.3f')} m from their "
                     f"nearest target point, GCR thresholds are a median {fmt(f['gcr_threshold_median_m'], '.3f')} m.")
    lines += ["", "GCR on the true matches at the true pose by the incidence angle of the source point's beam "
              "on its surface (0 = head-on, 90 = grazing), from a sample of the true matches:", ""]
    header = ["target", "incidence, deg", "true matches (sample)", "match distance median, m",
              "GCR threshold median, m", "GCR recall"]
    rows = []
    for kind, f in finding.items():
        for b in f["by_incidence"]:
            rows.append([kind, f"{b['incidence_lo_deg']:g}-{min(b['incidence_hi_deg'], 90):g}",
                         b["true_matches_sampled"], fmt(b["distance_median_m"], ".3f"),
                         fmt(b["gcr_threshold_median_m"], ".3f"), fmt(b["gcr_recall"], ".3f")])
    lines.append(markdown_table(header, rows, "llrrrr"))
    lines += ["The same by the source point's range (its distance from the sensor):", ""]
    header = ["target", "range, m", "true matches (sample)", "match distance median, m", "GCR threshold median, m",
              "GCR recall"]
    rows = [[kind, _range_label(b), b["true_matches_sampled"], fmt(b["distance_median_m"], ".3f"),
             fmt(b["gcr_threshold_median_m"], ".3f"), fmt(b["gcr_recall"], ".3f")]
            for kind, f in finding.items() for b in f.get("by_range", [])]
    lines.append(markdown_table(header, rows, "llrrrr"))
    lines += ["![true-match distances against GCR thresholds](match_distances.png)", ""]
    if "map" in finding:
        lines += ["## What GCR's threshold means against a map", ""]
        lines += map_threshold_lines(finding, params)
    return "\n".join(lines) + "\n"
