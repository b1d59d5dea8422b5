"""The leaderboard page: a table per scene family, figures per sequence; Markdown and one HTML page.

Per family and method, the figures are means over the family's sequences that the
method ran: KITTI t_err (%) and r_err (deg / 100 m) over 50-200 m segments, the
relative error over 10 m and 50 m windows (%, ``environment``), the aligned ATE
(m), the frame-to-frame RPE (cm), the vertical drift (|end height error| /
distance, %), the error along the truth's weakest direction over its weak
stretches (%, ``environment``; n/a where the truth has none), the success rate
(runs without a failure: a failed run, a divergence, or t_err above 10 %; a
failed run's figures stay in the means when it has them) and frames per second.
Methods are ranked by failures, then t_err; the best figure is bold.
"""

from __future__ import annotations

import math

import numpy as np

COLUMNS = (("t_err_pct", "t_err %", ".2f"), ("rel_10m_pct", "10 m window %", ".2f"),
           ("rel_50m_pct", "50 m window %", ".2f"), ("r_err_deg_per_100m", "r_err deg/100 m", ".3f"),
           ("ate_aligned_m", "ATE m", ".3f"), ("rpe_t_cm", "RPE cm", ".2f"),
           ("vertical_drift_pct", "vertical drift %", ".2f"), ("weak_dir_err_pct", "weak-direction err %", ".2f"))


def _mean(values) -> float:
    v = np.array([x for x in values if x is not None], dtype=float)
    v = v[np.isfinite(v)]
    return float(v.mean()) if len(v) else float("nan")


def family_rows(results: list[dict], methods: list) -> list[dict]:
    """Per method (in ``methods``' order): the means of ``COLUMNS``, failures, runs, frames/s."""
    rows = []
    for m in methods:
        mine = [r for r in results if r["method"] == m.name]
        ok = [r for r in mine if r["status"] == "ok"]
        row = {"method": m.name, "label": m.label, "runs": len(mine),
               "failures": sum(r["status"] != "ok" or r["figures"].get("failed", False) for r in mine),
               "frames_per_second": _mean(r.get("frames_per_second") for r in ok)}
        for key, _, _ in COLUMNS:
            vals = [r["figures"].get(key) for r in ok]
            row[key] = _mean(abs(v) if v is not None and key == "vertical_drift_pct" else v for v in vals)
        rows.append(row)
    return sorted(rows, key=lambda r: (r["failures"], r["t_err_pct"] if math.isfinite(r["t_err_pct"]) else math.inf))


def _cell(value: float, spec: str, best: bool) -> str:
    if not math.isfinite(value):
        return "n/a"
    text = format(value, spec)
    return f"**{text}**" if best else text


def table_markdown(rows: list[dict]) -> str:
    header = ["rank", "method", *(title for _, title, _ in COLUMNS), "success", "frames/s"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * 2 + "---:|" * (len(header) - 2)]
    best = {}
    for key, _, _ in COLUMNS:
        finite = [r[key] for r in rows if math.isfinite(r[key])]
        best[key] = min(finite) if finite else None
    for i, r in enumerate(rows, 1):
        cells = [_cell(r[key], spec, r[key] == best[key]) for key, _, spec in COLUMNS]
        ok = r["runs"] - r["failures"]
        success = f"{100.0 * ok / r['runs']:.0f} % ({ok}/{r['runs']})" if r["runs"] else "n/a"
        lines.append("| " + " | ".join([str(i), r["label"], *cells, success,
                                         _cell(r["frames_per_second"], ".1f", False)]) + " |")
    return "\n".join(lines)


__all__ = ["COLUMNS", "family_rows", "table_markdown"]
