"""Regression against ground truth: a small fixed suite, compared figure by figure with a baseline.

The suite is a sweep (``SUITE``: short sequences in three scenes x every
variant, at cruise speed so that 100 m segments exist). Its figures are
compared with a committed baseline file; a figure *fails* when it grows past

    allowed = baseline + max(relative * |baseline|, floor[figure])

with relative = 20 % and the floors of ``DEFAULT_FLOORS``. Why this tolerance:

- Run to run the figures are identical: the simulation is seeded and
  byte-identical, the odometry deterministic (measured: the suite run in
  worker processes and again in one process agrees to the last digit).
- Another machine can differ in the last bits of floating point (BLAS kernels,
  vector widths, summation order). Emulated by scaling every point by
  1 +- 1e-12: the suite's figures moved by at most 1.3 % (most by < 0.1 %).
  So 20 % is fifteen times that margin, while a real degradation is larger
  (in the forest, dropping the GCR, salo -> ncf, raises the KITTI error by
  28 %; dropping NCF and GCR, salo -> bl, by 171 %).
- The floors (a few per cent of the suite's typical figures) only matter
  when a figure is near zero, where a relative bound alone would be too tight.
- Degenerate sequences are left out on purpose: in the default tunnel the
  same 1e-12 perturbation moves BL's rotational error by 12 % (by 140 % with
  an earlier de-skew): ICP slips along the bore a little differently, so a
  harmless change of operation order could trip the guard there; on the
  default highway (signs 400 m apart) BL diverges. They belong in sweeps,
  not in a CI gate.

Figures that improve past the tolerance pass, with a note suggesting
``--update``. The baseline file (JSON) holds the suite, the tolerance and,
per run label, the figures; ``--update`` rewrites it from the current results,
keeping the tolerance. An external odometry (a command that reads a sequence
folder and writes KITTI poses) is evaluated the same way against its own
baseline file.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

from odometry.config import DEFAULT_VARIANT
from simlidar.formats.atomic import atomic_write_text

from .runner import SweepResult, run_sweep
from .spec import SweepSpec, spec_from_dict

# Short sequences (130 sweeps from 7 s on, at 10 m/s: ~130 m, so 100 m segments exist where the path
# is straight) in three well-conditioned geometries: a city (rich; its turns keep the path under 100 m,
# so ATE and RPE guard it), a forest road (trunks: where the NCF and GCR matter most), a highway with
# signs every 40 m and gantries every 120 m (sparse, but constrained along the road).
SUITE = {
    "name": "regress",
    "scenes": ["city", "forest", "highway"],
    "seeds": [0],
    "sensors": ["salo32"],
    "variants": ["bl", "ncf", "salo", DEFAULT_VARIANT],  # the paper's three and salo odometry's default
    "frames": 130,
    "speed_m_s": 10.0,
    "start_s": 7.0,  # past the start's acceleration (1.5 m/s^2 to 10 m/s)
    "scene_params": {"highway": {"sign_spacing_m": 40.0, "gantry_spacing_m": 120.0}},
    "keep_sequences": False,
}
DEFAULT_BASELINE = Path(__file__).resolve().parents[1] / "regress_baseline.json"
EXTERNAL_VARIANT = "external"

# Figures guarded (all errors: smaller is better) and their absolute floors, in their own units.
DEFAULT_RELATIVE = 0.20
DEFAULT_FLOORS = {
    "t_err_pct": 0.05,             # %: 5 cm over a 100 m segment
    "r_err_deg_per_100m": 0.05,    # deg / 100 m
    "t100_mean_m": 0.05,           # m per 100 m
    "ate_rmse_m": 0.05,            # m (unaligned: a small early heading change grows with distance)
    "ate_aligned_rmse_m": 0.005,   # m
    "rpe_t_rmse_m": 0.001,         # m per frame (the range noise is 2 cm)
    "rpe_r_rmse_deg": 0.005,       # deg per frame
}


class BaselineError(ValueError):
    """The baseline file is missing, unreadable, or for another suite; the message says which."""


def suite_spec(odometry_command: str | None = None, suite: SweepSpec | None = None,
               variant_name: str = EXTERNAL_VARIANT) -> SweepSpec:
    """The regression suite (or ``suite``); with ``odometry_command``, its only variant is that command."""
    spec = suite or spec_from_dict(SUITE, origin="regression suite")
    if odometry_command is None:
        return spec
    data = spec.to_dict()
    data.pop("configs")  # the built-in configs are not run against an external odometry
    data.update(variants=[variant_name], commands={variant_name: odometry_command}, odometry={})
    return spec_from_dict(data, origin="--odometry-command")


def _suite_identity(spec: SweepSpec) -> dict:
    """What a baseline must match: the sequences and the variants' names. Not where sequences live or
    whether they are kept, nor an external command's text (its options are what a user's CI is testing)."""
    data = spec.to_dict()
    data.pop("keep_sequences")
    data.pop("sequences", None)
    data.pop("commands")
    return json.loads(json.dumps(data))


@dataclass(frozen=True)
class Tolerance:
    """allowed = baseline + max(relative * |baseline|, floors[figure])."""

    relative: float = DEFAULT_RELATIVE
    floors: dict = field(default_factory=lambda: dict(DEFAULT_FLOORS))

    def allowed(self, figure: str, baseline: float) -> float:
        return baseline + max(self.relative * abs(baseline), self.floors[figure])

    def to_dict(self) -> dict:
        return {"relative": self.relative, "floors": dict(self.floors)}

    @classmethod
    def from_dict(cls, data: dict, origin: str) -> Tolerance:
        try:
            relative = float(data["relative"])
            floors = {str(k): float(v) for k, v in data["floors"].items()}
        except (KeyError, TypeError, ValueError, AttributeError):
            raise BaselineError(f"{origin}: 'tolerance' must be {{relative: number, floors: {{figure: number}}}}") \
                from None
        if relative < 0 or any(v < 0 for v in floors.values()) or not floors:
            raise BaselineError(f"{origin}: tolerance values must be >= 0 and name at least one figure")
        return cls(relative, floors)


@dataclass(frozen=True)
class Finding:
    """One comparison worth reporting. kind: "regression", "failed", "missing", "new" (fail) or "improved"."""

    label: str
    kind: str
    figure: str | None = None
    baseline: float | None = None
    current: float | None = None
    allowed: float | None = None
    detail: str = ""

    @property
    def fails(self) -> bool:
        return self.kind != "improved"

    def message(self) -> str:
        if self.kind in ("regression", "improved"):
            change = (self.current / self.baseline - 1.0) * 100.0 if self.baseline else math.inf
            verb = "grew" if self.kind == "regression" else "improved"
            return (f"{self.label}: {self.figure} {verb}: {self.current:.6g} now, baseline {self.baseline:.6g} "
                    f"({change:+.1f} %, allowed up to {self.allowed:.6g})")
        return f"{self.label}: {self.detail}"


@dataclass
class RegressReport:
    """The comparison of a suite's rows with a baseline: every run's figures and the findings."""

    rows: list[dict]
    baseline: dict
    tolerance: Tolerance
    findings: list[Finding]

    @property
    def passed(self) -> bool:
        return not any(f.fails for f in self.findings)

    @property
    def failures(self) -> list[Finding]:
        return [f for f in self.findings if f.fails]


# ---------------------------------------------------------------- baseline file
def read_baseline(path: str | Path) -> dict:
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise BaselineError(f"{path}: no baseline file; write one with `salo regress --update`") from None
    except (OSError, json.JSONDecodeError) as exc:
        raise BaselineError(f"{path}: cannot read the baseline ({exc})") from None
    if not isinstance(data, dict) or not isinstance(data.get("runs"), dict):
        raise BaselineError(f"{path}: not a salo regress baseline (no 'runs' mapping)")
    return data


def baseline_from_rows(rows: list[dict], spec: SweepSpec, tolerance: Tolerance) -> dict:
    """The baseline document for ``rows`` (every run must have succeeded)."""
    from .tasks import versions

    failed = [r["label"] for r in rows if r["status"] != "ok"]
    if failed:
        raise BaselineError(f"cannot write a baseline from failed runs: {', '.join(failed)}")
    return {
        "about": "salo regress baseline: figures per run of the suite; rewrite with `salo regress --update`",
        "suite": _suite_identity(spec),
        "tolerance": tolerance.to_dict(),
        "versions": versions(),
        "runs": {r["label"]: {"key": r["key"], **{f: r[f] for f in tolerance.floors}} for r in rows},
    }


def write_baseline(path: str | Path, document: dict) -> None:
    atomic_write_text(path, json.dumps(document, indent=1, allow_nan=False) + "\n")


# ---------------------------------------------------------------- comparison
def check_suite(baseline: dict, spec: SweepSpec, origin: str = "baseline") -> None:
    """BaselineError unless ``baseline`` was written for this suite (checked before any work)."""
    if baseline.get("suite") != _suite_identity(spec):
        raise BaselineError(f"{origin}: written for another suite (scenes, frames, variants or parameters "
                            "differ); rewrite it with `salo regress --update`")


def compare(rows: list[dict], baseline: dict, spec: SweepSpec, origin: str = "baseline") -> RegressReport:
    """Compare the suite's rows with a baseline document (``read_baseline``)."""
    check_suite(baseline, spec, origin)
    tolerance = Tolerance.from_dict(baseline.get("tolerance", {}), origin)
    findings: list[Finding] = []
    base_runs = baseline["runs"]
    for row in rows:
        label = row["label"]
        if label not in base_runs:
            findings.append(Finding(label, "new", detail="no baseline figures for this run "
                                                         "(rewrite the baseline with --update)"))
            continue
        if row["status"] != "ok":
            findings.append(Finding(label, "failed", detail=f"the run failed: {row['error']}"))
            continue
        for figure in tolerance.floors:
            base, now = base_runs[label].get(figure), row.get(figure)
            if base is None:
                continue  # the baseline has no such figure (e.g. no 100 m segment): nothing to guard
            if now is None or not math.isfinite(now):
                findings.append(Finding(label, "missing", figure, base, None,
                                        detail=f"{figure} is missing now, baseline {base:.6g}"))
                continue
            allowed = tolerance.allowed(figure, base)
            if now > allowed:
                findings.append(Finding(label, "regression", figure, base, now, allowed))
            elif now < base - max(tolerance.relative * abs(base), tolerance.floors[figure]):
                findings.append(Finding(label, "improved", figure, base, now, allowed))
    for label in base_runs:
        if label not in {r["label"] for r in rows}:
            findings.append(Finding(label, "missing", detail="in the baseline but not run"))
    return RegressReport(rows, baseline, tolerance, findings)


__all__ = ["DEFAULT_BASELINE", "SUITE", "BaselineError", "Finding", "RegressReport", "Tolerance", "baseline_from_rows",
           "check_suite", "compare", "read_baseline", "suite_spec", "write_baseline"]


# ---------------------------------------------------------------- the run
@dataclass
class RegressRun:
    """A finished ``regress``: the suite's sweep (``SweepResult``: rows, seconds, ...), the comparison with
    the baseline (``report``; None when the baseline was rewritten) and the tolerance applied or kept."""

    result: SweepResult
    report: RegressReport | None
    tolerance: Tolerance


def regress(spec: SweepSpec, out: str | Path, executor, baseline_path: str | Path, *, update: bool = False,
            baseline: dict | None = None, on_plan=None, on_result=None,
            command_timeout_s: float | None = None) -> RegressRun:
    """Run every run of the suite ``spec`` afresh into ``out`` and compare its figures with the baseline.

    baseline: the baseline document, already read and checked against the suite
    (``read_baseline``, ``check_suite``: a caller does it before the work; read here
    when None). With ``update`` the baseline file is rewritten from this run
    instead, keeping its tolerance (the default one for a new file). on_plan,
    on_result, command_timeout_s: as ``run_sweep``'s. Raises BaselineError.
    """
    if not update and baseline is None:
        baseline = read_baseline(baseline_path)
        check_suite(baseline, spec, str(baseline_path))
    result = run_sweep(spec, out, executor, rerun=True, retry_failed=True, on_plan=on_plan, on_result=on_result,
                       command_timeout_s=command_timeout_s, report=False)  # the figures are the report
    if update:
        old = read_baseline(baseline_path) if Path(baseline_path).is_file() else {}
        tolerance = Tolerance.from_dict(old["tolerance"], str(baseline_path)) if "tolerance" in old else Tolerance()
        write_baseline(baseline_path, baseline_from_rows(result.rows, spec, tolerance))
        return RegressRun(result, None, tolerance)
    report = compare(result.rows, baseline, spec, origin=str(baseline_path))
    return RegressRun(result, report, report.tolerance)
