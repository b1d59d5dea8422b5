"""NCF on known noise: the predicted normal uncertainty against the true normal error.

For every ICP point of a few simulated scans (voxel centroids, normals from
their k nearest raw returns exactly as ``odometry.filters`` computes them),
the normal covariance filter predicts the covariance of the normal
(``odometry.ncf.normal_covariance``) and the simulator knows the true normal
of the surface (the sidecar's ``normal`` of the centroid's nearest return).
The study reports, per noise model and range-noise level:

- calibration: points binned by their predicted 1-sigma tilt in the least
  certain direction (``max_std``, the quantity c_tau thresholds); in each bin
  the predicted RMS tilt ``sqrt(c_minor + c_major)`` against the actual RMS
  angle between estimated and true normal, and the squared Mahalanobis error
  of the tilt ``d2 = e^T C^-1 e`` (chi-square with 2 degrees of freedom when
  calibrated: median 1.39, mean 2, 95 % below 5.99). The RMS and the mean of
  d2 are dominated by the few gross errors the noise model cannot predict
  (model error: curvature, a second surface); the median of d2 and the share
  within the 95 % bound describe the bulk;
- the filter: for each c_tau (as an angle), the share of points kept and the
  true normal error of the kept and of the rejected points.

Two noise models: "range" (sensor-aware: range noise along each beam, the
sensor's sigma) and "isotropic" (the paper's sphere, with the same sigma per
coordinate). The NCF models noise only: points whose neighbourhood spans two
surfaces (an edge, a kerb, a pole against a wall) have a wrong normal the
noise model cannot predict. The calibration is therefore also given on
"single-surface" points: all k neighbours on the same object with true
normals within 5 deg of each other.

Scans are de-skewed with the true motion, so the study measures the filter,
not the de-skew.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tools.records import RunRecord, fmt, markdown_table, write_csv, write_json
from tools.sequence_cache import DEFAULT_CACHE_LIMIT_BYTES, SequenceSpec, load_sequence

log = logging.getLogger(__name__)

DEFAULT_NOISE_LEVELS_M = (0.005, 0.01, 0.02, 0.04)
DEFAULT_C_TAU_DEG = (0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 7.0, 10.0, 15.0, 20.0)
DEFAULT_BIN_EDGES_DEG = (0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0, 12.0, 20.0, math.inf)
MODELS = ("range", "isotropic")
SINGLE_SURFACE_MAX_SPREAD_DEG = 5.0
CHI2_2DOF_95 = 5.991464547107979  # 95 % quantile of chi-square with 2 degrees of freedom
CHI2_2DOF_MEDIAN = 2.0 * math.log(2.0)  # its median, 1.386


def _default_scans() -> tuple[SequenceSpec, ...]:
    # Different worlds, each one sweep at cruise speed (start 10 s along the path).
    return tuple(SequenceSpec(scene, seed, frames=2, start_s=10.0) for scene, seed in
                 (("city", 1), ("city", 2), ("tunnel", 1), ("open", 1)))


@dataclass(frozen=True)
class NcfStudyParams:
    """Sizes of the study.

    noise_levels_m: range noise sigmas simulated, m. scans: the sequences (first
    frame of each) simulated at every level (their own noise_std_m is replaced).
    max_points_per_scan: subsample the ICP points (None: all). c_tau_deg: the
    thresholds swept (as 1-sigma angles). bin_edges_deg: calibration bins of the
    predicted max std. models: "range" and/or "isotropic". seed: subsampling.
    config_overrides: changes to the ``salo`` config, nested by stage as in YAML (voxel size, k).
    """

    noise_levels_m: tuple[float, ...] = DEFAULT_NOISE_LEVELS_M
    scans: tuple[SequenceSpec, ...] = field(default_factory=_default_scans)
    max_points_per_scan: int | None = None
    c_tau_deg: tuple[float, ...] = DEFAULT_C_TAU_DEG
    bin_edges_deg: tuple[float, ...] = DEFAULT_BIN_EDGES_DEG
    models: tuple[str, ...] = MODELS
    seed: int = 0
    config_overrides: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {
            "noise_levels_m": list(self.noise_levels_m),
            "scans": [s.to_dict() for s in self.scans],
            "max_points_per_scan": self.max_points_per_scan,
            "c_tau_deg": list(self.c_tau_deg),
            "bin_edges_deg": [None if math.isinf(b) else b for b in self.bin_edges_deg],
            "models": list(self.models),
            "seed": self.seed,
            "config_overrides": dict(self.config_overrides),
            "max_curvature": self.config().filter.max_curvature,
            "ncf_max_normal_std_deg": self.config().ncf.max_normal_std_deg,
            "voxel_size_m": self.config().filter.voxel_size_m,
            "normal_neighbours": self.config().filter.normal_neighbours,
        }

    def config(self):
        """The ``salo`` odometry config with the overrides: voxel size, k and the curvature bound used here."""
        from odometry.config import variant

        return variant("salo").replace(**self.config_overrides)


@dataclass
class NormalSamples:
    """Per ICP point of all scans at one noise level (M points).

    error_deg: (M,) angle between estimated and true normal. single_surface: (M,) bool.
    curvature: (M,) PCL curvature. per model: max_std_deg (M,), rms_std_deg (M,)
    predicted RMS tilt, mahalanobis2 (M,) squared Mahalanobis tilt error (nan without a finite prediction).
    """

    error_deg: np.ndarray
    single_surface: np.ndarray
    curvature: np.ndarray
    max_std_deg: dict
    rms_std_deg: dict
    mahalanobis2: dict


def scan_samples(sequence, k: int, config, models, rng: np.random.Generator, max_points: int | None) -> NormalSamples:
    """The normals of frame k's ICP points, their true error and the NCF's predictions."""
    from odometry.deskew import deskew
    from odometry.kdtree import KDTree
    from odometry.ncf import IsotropicNoise, RangeNoise, normal_covariance
    from odometry.normals import angle_between_normals_rad, estimate_normals
    from odometry.preparation import clean_scan
    from odometry.voxels import voxel_centroids

    from .rejector_study import true_motion

    sensor = sequence.sensor
    frame = sequence[k]
    clean = clean_scan(frame.points, frame.time_s, None, config)
    rows = clean.kept_rows
    period = float(np.diff(sequence.times[:2])[0])
    raw = deskew(clean.points, clean.times_s, true_motion(sequence.poses, k), period)
    centroids = voxel_centroids(raw, config.filter.voxel_size_m)
    if max_points is not None and len(centroids) > max_points:
        centroids = centroids[np.sort(rng.choice(len(centroids), max_points, replace=False))]
    tree = KDTree(raw)
    est = estimate_normals(raw, k=config.filter.normal_neighbours, query_points=centroids, tree=tree)
    car = frame.fields
    nb_rows = rows[est.neighbour_indices]  # (M, k) sidecar rows of the neighbours
    true_n = np.asarray(car["normal"][nb_rows[:, 0]], dtype=np.float64)  # the nearest return's surface
    err = angle_between_normals_rad(est.normals, true_n)
    nb_normals = np.asarray(car["normal"][nb_rows], dtype=np.float64)
    spread = np.degrees(np.arccos(np.clip(np.einsum("mkj,mj->mk", nb_normals, true_n), -1.0, 1.0))).max(axis=1)
    same_obj = np.all(car["object_id"][nb_rows] == car["object_id"][nb_rows[:, :1]], axis=1)
    single = same_obj & (spread < SINGLE_SURFACE_MAX_SPREAD_DEG)
    # The tilt of the true normal in the estimated normal's tangent plane (sign-aligned).
    sign = np.where(np.einsum("mj,mj->m", true_n, est.normals) < 0, -1.0, 1.0)
    e = true_n * sign[:, None]
    P = raw[est.neighbour_indices]
    max_std, rms_std, maha = {}, {}, {}
    sigma = sensor.range_noise_std_m
    for model in models:
        noise = RangeNoise(range_noise_std_m=sigma) if model == "range" else IsotropicNoise(point_noise_std_m=sigma)
        nc = normal_covariance(P, noise, pca=est, noise_free_gaps=config.ncf.noise_free_gaps)  # as the odometry
        lam = nc.eigenvalues_rad2
        a = np.einsum("mj,mj->m", e, nc.eigenvectors[:, :, 1])
        b = np.einsum("mj,mj->m", e, nc.eigenvectors[:, :, 2])
        with np.errstate(divide="ignore", invalid="ignore"):
            d2 = a * a / lam[:, 1] + b * b / lam[:, 2]
        # No finite prediction (degenerate neighbourhood): no Mahalanobis error (nan), not a perfect one (0).
        maha[model] = np.where(np.isfinite(lam[:, 2]), d2, np.nan)
        max_std[model] = np.degrees(np.sqrt(lam[:, 2]))
        rms_std[model] = np.degrees(np.sqrt(lam[:, 1] + lam[:, 2]))
    return NormalSamples(np.degrees(err), single, est.curvature, max_std, rms_std, maha)


def _concat(parts: list[NormalSamples], models) -> NormalSamples:
    return NormalSamples(
        np.concatenate([p.error_deg for p in parts]),
        np.concatenate([p.single_surface for p in parts]),
        np.concatenate([p.curvature for p in parts]),
        {m: np.concatenate([p.max_std_deg[m] for p in parts]) for m in models},
        {m: np.concatenate([p.rms_std_deg[m] for p in parts]) for m in models},
        {m: np.concatenate([p.mahalanobis2[m] for p in parts]) for m in models},
    )


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if len(x) else float("nan")


def calibration_rows(s: NormalSamples, model: str, edges, noise_m: float, subset: str) -> list[dict]:
    """One row per bin of predicted max std (infinite predictions get their own row)."""
    sel = s.single_surface if subset == "single-surface" else np.ones(len(s.error_deg), dtype=bool)
    pred = s.max_std_deg[model]
    rows = []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        m = sel & (pred >= lo) & (pred < hi)
        rows.append(_calibration_row(s, model, m, noise_m, subset, lo, hi))
    rows.append(_calibration_row(s, model, sel & ~np.isfinite(pred), noise_m, subset, math.inf, math.inf))
    return rows


def _calibration_row(s, model, m, noise_m, subset, lo, hi) -> dict:
    err, rms_pred, d2 = s.error_deg[m], s.rms_std_deg[model][m], s.mahalanobis2[model][m]
    finite = np.isfinite(rms_pred)
    return {
        "model": model, "noise_std_m": noise_m, "subset": subset,
        "bin_lo_deg": lo, "bin_hi_deg": hi if math.isfinite(hi) else None, "count": int(m.sum()),
        "predicted_max_std_median_deg": float(np.median(s.max_std_deg[model][m])) if m.any() else float("nan"),
        "predicted_rms_deg": _rms(rms_pred[finite]) if finite.any() else float("nan"),
        "actual_rms_deg": _rms(err), "actual_median_deg": float(np.median(err)) if len(err) else float("nan"),
        "mahalanobis2_mean": float(np.mean(d2[np.isfinite(d2)])) if np.isfinite(d2).any() else float("nan"),
        "mahalanobis2_median": float(np.median(d2[~np.isnan(d2)])) if (~np.isnan(d2)).any() else float("nan"),
        "within_95": float(np.mean(d2[~np.isnan(d2)] < CHI2_2DOF_95)) if (~np.isnan(d2)).any() else float("nan"),
    }


def ctau_rows(s: NormalSamples, model: str, c_tau_deg, noise_m: float, max_curvature: float) -> list[dict]:
    """Kept share and true error of kept / rejected points for each c_tau.

    NCF alone, as the filter applies it; and NCF followed by the curvature
    filter (``max_curvature``), as the odometry applies both.
    """
    pred, err = s.max_std_deg[model], s.error_deg
    with np.errstate(invalid="ignore"):
        flat = s.curvature <= max_curvature
    rows = []
    for c in c_tau_deg:
        keep = pred < c  # the filter rejects C_22 >= c_tau; nan / inf (degenerate) are rejected
        kept, rej, both = err[keep], err[~keep], err[keep & flat]
        rows.append({
            "model": model, "noise_std_m": noise_m, "c_tau_deg": c, "points": len(err),
            "kept_fraction": float(keep.mean()) if len(err) else float("nan"),
            "kept_error_median_deg": float(np.median(kept)) if len(kept) else float("nan"),
            "kept_error_p90_deg": float(np.percentile(kept, 90)) if len(kept) else float("nan"),
            "rejected_error_median_deg": float(np.median(rej)) if len(rej) else float("nan"),
            "rejected_error_p90_deg": float(np.percentile(rej, 90)) if len(rej) else float("nan"),
            "kept_single_surface": float(s.single_surface[keep].mean()) if keep.any() else float("nan"),
            "with_curvature_kept_fraction": float((keep & flat).mean()) if len(err) else float("nan"),
            "with_curvature_error_median_deg": float(np.median(both)) if len(both) else float("nan"),
            "with_curvature_error_p90_deg": float(np.percentile(both, 90)) if len(both) else float("nan"),
        })
    return rows


@dataclass
class NcfStudyResult:
    calibration: list[dict]
    ctau: list[dict]
    overview: list[dict]


def run_ncf_study(params: NcfStudyParams, cache_dir: str | Path | None, progress: bool = False,
                  cache_limit_bytes: int | None = DEFAULT_CACHE_LIMIT_BYTES) -> NcfStudyResult:
    """Simulate the scans at each noise level and measure (see the module notes); writes nothing.

    cache_dir: the sequence cache, or None: every scan simulated in memory (with its truth).
    """
    from tqdm import tqdm

    config = params.config()
    calib, ctau, overview = [], [], []
    jobs = [(noise, spec) for noise in params.noise_levels_m for spec in params.scans]
    per_level: dict[float, list[NormalSamples]] = {}
    for j, (noise, spec) in enumerate(tqdm(jobs, desc="ncf study", unit="scan", disable=not progress,
                                           dynamic_ncols=True)):
        seq = load_sequence(spec.with_changes(noise_std_m=noise), cache_dir, fields="truth",
                            cache_limit_bytes=cache_limit_bytes)
        rng = np.random.default_rng([params.seed, j])
        per_level.setdefault(noise, []).append(
            scan_samples(seq, 0, config, params.models, rng, params.max_points_per_scan))
    for noise, parts in per_level.items():
        s = _concat(parts, params.models)
        for model in params.models:
            for subset in ("all", "single-surface"):
                calib += calibration_rows(s, model, params.bin_edges_deg, noise, subset)
            ctau += ctau_rows(s, model, params.c_tau_deg, noise, config.filter.max_curvature)
            d2 = s.mahalanobis2[model]
            finite = np.isfinite(s.max_std_deg[model])
            overview.append({
                "model": model, "noise_std_m": noise, "points": len(s.error_deg),
                "single_surface_fraction": float(s.single_surface.mean()),
                "finite_prediction_fraction": float(finite.mean()),
                "error_median_deg": float(np.median(s.error_deg)),
                "single_surface_error_median_deg": float(np.median(s.error_deg[s.single_surface]))
                if s.single_surface.any() else float("nan"),
                "predicted_max_std_median_deg": float(np.median(s.max_std_deg[model][finite]))
                if finite.any() else float("nan"),
                "single_surface_mahalanobis2_median": float(np.median(d2[s.single_surface & ~np.isnan(d2)]))
                if (s.single_surface & ~np.isnan(d2)).any() else float("nan"),
                "single_surface_within_95": float(np.mean(d2[s.single_surface & ~np.isnan(d2)] < CHI2_2DOF_95))
                if (s.single_surface & ~np.isnan(d2)).any() else float("nan"),
            })
    return NcfStudyResult(calib, ctau, overview)


def write_ncf_study(result: NcfStudyResult, record: RunRecord) -> None:
    """results.json, CSV tables, summary.md and the figures into the run folder."""
    from . import plots

    write_csv(record.path("calibration.csv"), result.calibration, list(result.calibration[0]))
    write_csv(record.path("c_tau.csv"), result.ctau, list(result.ctau[0]))
    write_csv(record.path("overview.csv"), result.overview, list(result.overview[0]))
    write_json(record.path("results.json"), {"experiment": "ncf", "params": record.params,
                                             "overview": result.overview, "calibration": result.calibration,
                                             "c_tau": result.ctau})
    plots.ncf_calibration(record.path("calibration.png"), result.calibration)
    plots.ncf_ctau(record.path("c_tau.png"), result.ctau, default_c_tau_deg=record.params.get("ncf_max_normal_std_deg"))
    record.write_text("summary.md", ncf_markdown(result, record.params))


def ncf_markdown(result: NcfStudyResult, params: dict) -> str:
    lines = ["# NCF on known noise: predicted normal uncertainty against the true normal error", ""]
    scans = ", ".join(f"{s['name']} (t = {s['start_s']:g} s)" for s in params["scans"])
    lines.append(f"Scans: {scans}, sensor {params['scans'][0]['sensor']}, range noise "
                 f"{', '.join(f'{1000 * n:g} mm' for n in params['noise_levels_m'])} (1 sigma). Points: voxel "
                 "centroids with kNN normals from the de-skewed raw scan, as the odometry computes them. "
                 "\"range\" = sensor-aware model (noise along each beam), \"isotropic\" = the paper's sphere "
                 "with the same sigma. Calibrated: predicted RMS tilt = actual RMS error, median Mahalanobis^2 = 1.39, "
                 "95 % inside the chi-square(2) bound. \"Single-surface\": all k neighbours on one object with "
                 "true normals within 5 deg; \"degenerate\": the model gives no finite covariance (rejected by "
                 "any c_tau).")
    lines += ["", "## Overview", ""]
    header = ["model", "noise, mm", "points", "single-surface share", "median error, deg",
              "median error single-surface, deg", "median predicted max std, deg", "finite prediction share",
              "Mahalanobis^2 median (single)", "within 95 % (single)"]
    rows = [[r["model"], f"{1000 * r['noise_std_m']:g}", r["points"], fmt(r["single_surface_fraction"], ".2f"),
             fmt(r["error_median_deg"], ".2f"), fmt(r["single_surface_error_median_deg"], ".2f"),
             fmt(r["predicted_max_std_median_deg"], ".2f"), fmt(r["finite_prediction_fraction"], ".2f"),
             fmt(r["single_surface_mahalanobis2_median"], ".2f"), fmt(r["single_surface_within_95"], ".2f")]
            for r in result.overview]
    lines.append(markdown_table(header, rows, "lrrrrrrrrr"))
    lines += ["## Calibration (single-surface points)", ""]
    header = ["model", "noise, mm", "predicted max std bin, deg", "n", "predicted RMS, deg", "actual RMS, deg",
              "actual median, deg", "Mahalanobis^2 median", "within 95 %"]
    rows = []
    for r in result.calibration:
        if r["subset"] != "single-surface" or r["count"] == 0:
            continue
        b = "inf (degenerate)" if math.isinf(r["bin_lo_deg"]) else \
            f"{r['bin_lo_deg']:g}-{fmt(r['bin_hi_deg'], 'g') if r['bin_hi_deg'] is not None else 'inf'}"
        rows.append([r["model"], f"{1000 * r['noise_std_m']:g}", b, r["count"], fmt(r["predicted_rms_deg"], ".2f"),
                     fmt(r["actual_rms_deg"], ".2f"), fmt(r["actual_median_deg"], ".2f"),
                     fmt(r["mahalanobis2_median"], ".2f"), fmt(r["within_95"], ".2f")])
    lines.append(markdown_table(header, rows, "lrlrrrrrr"))
    lines += ["All points (edges included) are in `calibration.csv` (subset \"all\").", "",
              "![calibration](calibration.png)", "", "## The filter as c_tau varies", ""]
    lines.append("\"+ curvature\": the points NCF keeps that the odometry's curvature filter (PCL curvature <= "
                 f"{params['max_curvature']:g}) keeps too.")
    lines.append("")
    header = ["model", "noise, mm", "c_tau, deg", "kept", "kept: median error, deg", "kept: p90, deg",
              "rejected: median error, deg", "rejected: p90, deg", "+ curvature: kept",
              "+ curvature: median, deg", "+ curvature: p90, deg"]
    rows = [[r["model"], f"{1000 * r['noise_std_m']:g}", f"{r['c_tau_deg']:g}", fmt(r["kept_fraction"], ".3f"),
             fmt(r["kept_error_median_deg"], ".2f"), fmt(r["kept_error_p90_deg"], ".2f"),
             fmt(r["rejected_error_median_deg"], ".2f"), fmt(r["rejected_error_p90_deg"], ".2f"),
             fmt(r["with_curvature_kept_fraction"], ".3f"), fmt(r["with_curvature_error_median_deg"], ".2f"),
             fmt(r["with_curvature_error_p90_deg"], ".2f")]
            for r in result.ctau]
    lines.append(markdown_table(header, rows, "lrrrrrrrrrr"))
    lines += ["![kept share and errors against c_tau](c_tau.png)", ""]
    return "\n".join(lines) + "\n"
