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
keeping the tolerance.

Any method (``tools.methods``: one of our configurations, a peer, a plug-in, an
external command) is guarded the same way against a baseline of its own, one
file per method and suite (``method_baseline_path``: ``DIR/SUITE/METHOD.json``):
its document names the method, and a baseline of another method or suite is
refused with the flag that fixes it (``--method NAME`` for a name, ``--suite`` for
a suite), never with a rewrite. Every method runs on the staged input of
``tools.staging``: scans, sensor, times and the opted-in fields, no ground truth.
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
# Where per-method baselines go by default, relative to the working folder (a user's repository).
DEFAULT_BASELINE_DIR = Path("regress-baselines")

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


def suite_spec(suite: SweepSpec | None = None) -> SweepSpec:
    """The regression suite (or ``suite``), with its own variants."""
    return suite or spec_from_dict(SUITE, origin="regression suite")


def method_suite_spec(methods: list[str], suite: SweepSpec | None = None, commands: dict[str, str] | None = None,
                      overrides: dict | None = None, fields: tuple[str, ...] | None = None) -> SweepSpec:
    """The suite's sequences with ``methods`` as its variants.

    methods: names of ``tools.methods`` (ours, including ``default``; peers; plug-ins) or keys of
    ``commands`` (external commands; ``tools.methods.MethodError`` for an unknown name). overrides:
    our configurations' changes, nested by stage (``--set``). fields: the per-point fields handed to
    the methods (default: the suite's).
    """
    from tools.methods import method_from_name

    commands = dict(commands or {})
    for m in methods:
        if m not in commands:
            method_from_name(m)  # MethodError naming the known methods
    spec = suite_spec(suite)
    data = spec.to_dict()
    data.pop("configs")
    configs = {m: {"base": DEFAULT_VARIANT} for m in methods if m == "default" and m not in commands}
    data.update(variants=list(methods), commands=commands, configs=configs, odometry=dict(overrides or {}))
    if fields is not None:
        data["fields"] = list(fields) or ["none"]
    return spec_from_dict(data, origin="--method")


def _suite_identity(spec: SweepSpec) -> dict:
    """What a baseline must match: the sequences and the variants' names. Not where sequences live or
    whether they are kept, nor an external command's text (its options are what a user's CI is testing)."""
    data = spec.to_dict()
    data.pop("keep_sequences")
    data.pop("sequences", None)
    data.pop("commands")
    return json.loads(json.dumps(data))


def _method_suite_identity(spec: SweepSpec) -> dict:
    """What a method's baseline must match: the sequences and what the method is handed. Not the
    method's own settings (commands, configs, overrides): changing them is what CI tests."""
    data = _suite_identity(spec)
    for key in ("variants", "configs", "odometry"):
        data.pop(key)
    return data


def method_baseline_path(method: str, suite_name: str, folder: str | Path = DEFAULT_BASELINE_DIR) -> Path:
    """A method's baseline file for a suite: ``folder/SUITE/METHOD.json``."""
    return Path(folder) / suite_name / f"{method}.json"


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
def read_baseline(path: str | Path, method: str | None = None) -> dict:
    """The baseline document at ``path`` (of ``method``, for the message when it is missing)."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        what = f"salo regress --method {method} ... --update" if method else "salo regress --update"
        raise BaselineError(f"{path}: no baseline file{f' for method {method!r}' if method else ''}; write it "
                            f"once with `{what}` (and commit it)") from None
    except (OSError, json.JSONDecodeError) as exc:
        raise BaselineError(f"{path}: cannot read the baseline ({exc})") from None
    if not isinstance(data, dict) or not isinstance(data.get("runs"), dict):
        raise BaselineError(f"{path}: not a salo regress baseline (no 'runs' mapping)")
    return data


def baseline_from_rows(rows: list[dict], spec: SweepSpec, tolerance: Tolerance, method: str | None = None) -> dict:
    """The baseline document for ``rows`` (every run must have succeeded); of one ``method``'s rows when given."""
    from .tasks import versions

    failed = [f"{r['label']} ({r['error']})" for r in rows if r["status"] != "ok"]
    if failed:
        raise BaselineError(f"cannot write a baseline from failed runs: {'; '.join(failed)}")
    doc = {"about": "salo regress baseline: figures per run of the suite; rewrite with `salo regress --update`"}
    if method is not None:
        doc = {"about": f"salo regress baseline of method {method}: figures per run of the suite; rewrite with "
                        f"`salo regress --method {method} ... --update`", "method": method,
               "suite": _method_suite_identity(spec)}
    else:
        doc["suite"] = _suite_identity(spec)
    return {
        **doc,
        "tolerance": tolerance.to_dict(),
        "versions": versions(),
        "runs": {r["label"]: {"key": r["key"], **{f: r[f] for f in tolerance.floors}} for r in rows},
    }


def write_baseline(path: str | Path, document: dict) -> None:
    atomic_write_text(path, json.dumps(document, indent=1, allow_nan=False) + "\n")


# ---------------------------------------------------------------- comparison
def _differences(a: dict, b: dict) -> list[str]:
    """Top-level keys whose values differ, as 'KEY (BASELINE's vs this run's)'."""
    return [f"{k} ({json.dumps(a.get(k))} there, {json.dumps(b.get(k))} here)" for k in sorted(set(a) | set(b))
            if a.get(k) != b.get(k)]


def check_suite(baseline: dict, spec: SweepSpec, origin: str = "baseline", method: str | None = None) -> None:
    """BaselineError unless ``baseline`` was written for this suite (and for ``method``, when given);
    checked before any work. The message names what differs and the flag that fixes it."""
    if method is not None:
        written_for = baseline.get("method")
        if written_for is None:
            names = sorted({label.rsplit("/", 1)[-1] for label in baseline.get("runs", {})})
            raise BaselineError(f"{origin}: a suite baseline of the variants {', '.join(names)}, not one method's; "
                                f"give --baseline a file of method {method!r}'s own (or leave --baseline out: "
                                f"{method_baseline_path(method, spec.name)})")
        if written_for != method:
            raise BaselineError(f"{origin}: the baseline of method {written_for!r}, and this run's method is "
                                f"{method!r}: give --method {written_for} (the name it was written under), or "
                                f"another --baseline for {method!r}")
        here = _method_suite_identity(spec)
    else:
        if baseline.get("method") is not None:
            raise BaselineError(f"{origin}: the baseline of method {baseline['method']!r}: give "
                                f"--method {baseline['method']}")
        here = _suite_identity(spec)
    there = baseline.get("suite")
    if there != here:
        differ = _differences(there or {}, here)
        what = "; ".join(differ) or "its suite is not recorded"
        if method is None and differ and all(d.startswith(("variants", "configs")) for d in differ):
            raise BaselineError(f"{origin}: written for other variants: {what}; a method of your own is guarded "
                                "with --method NAME against a baseline of its own")
        raise BaselineError(f"{origin}: written for another suite: {what}. Run the suite it was written for "
                            f"(--suite); if the suite changed on purpose, write a new baseline with --update")


def compare(rows: list[dict], baseline: dict, spec: SweepSpec, origin: str = "baseline",
            method: str | None = None) -> RegressReport:
    """Compare the suite's rows (of ``method``, when given) with a baseline document (``read_baseline``)."""
    check_suite(baseline, spec, origin, method)
    if method is not None:
        rows = [r for r in rows if r["variant"] == method]
    tolerance = Tolerance.from_dict(baseline.get("tolerance", {}), origin)
    findings: list[Finding] = []
    base_runs = baseline["runs"]
    for row in rows:
        label = row["label"]
        if label not in base_runs:
            findings.append(Finding(label, "new", detail="no baseline figures for this run "
                                                         "(a run the baseline's suite did not have)"))
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


__all__ = ["DEFAULT_BASELINE", "DEFAULT_BASELINE_DIR", "SUITE", "BaselineError", "Finding", "MethodsRegressRun",
           "RegressReport", "Tolerance", "baseline_from_rows", "check_suite", "compare", "method_baseline_path",
           "method_suite_spec", "read_baseline", "regress", "regress_methods", "suite_spec", "write_baseline"]


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


@dataclass
class MethodsRegressRun:
    """A finished ``regress_methods``: the sweep, and per method its report (None when its baseline was
    rewritten) and tolerance."""

    result: SweepResult
    reports: dict[str, RegressReport | None]
    tolerances: dict[str, Tolerance]


def regress_methods(spec: SweepSpec, out: str | Path, executor, baselines: dict[str, Path], *, update: bool = False,
                    documents: dict[str, dict] | None = None, on_plan=None, on_result=None,
                    command_timeout_s: float | None = None) -> MethodsRegressRun:
    """Run the suite ``spec`` (``method_suite_spec``) and compare each method with its own baseline.

    baselines: method -> its baseline file. documents: the baselines, already read and checked
    (``read_baseline``, ``check_suite(..., method=)``; read here when missing). With ``update``
    each method's file is rewritten from this run, keeping its tolerance.
    """
    documents = dict(documents or {})
    if not update:
        for method, path in baselines.items():
            if method not in documents:
                documents[method] = read_baseline(path, method)
                check_suite(documents[method], spec, str(path), method)
    result = run_sweep(spec, out, executor, rerun=True, retry_failed=True, on_plan=on_plan, on_result=on_result,
                       command_timeout_s=command_timeout_s, report=False)
    reports: dict[str, RegressReport | None] = {}
    tolerances: dict[str, Tolerance] = {}
    for method, path in baselines.items():
        if update:
            old = read_baseline(path) if Path(path).is_file() else {}
            tolerance = Tolerance.from_dict(old["tolerance"], str(path)) if "tolerance" in old else Tolerance()
            rows = [r for r in result.rows if r["variant"] == method]
            Path(path).parent.mkdir(parents=True, exist_ok=True)
            write_baseline(path, baseline_from_rows(rows, spec, tolerance, method))
            reports[method], tolerances[method] = None, tolerance
        else:
            report = compare(result.rows, documents[method], spec, str(path), method)
            reports[method], tolerances[method] = report, report.tolerance
    return MethodsRegressRun(result, reports, tolerances)
