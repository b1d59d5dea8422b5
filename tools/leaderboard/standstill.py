"""The stress suite's table: per sequence and method, the end's position error and the motion invented standing still.

The suite's tables (``page``) give means per group; the stress scenes are single
sequences made to break a method one way each, so their figures are listed one by one:
the error of the last pose (m) and, where the sensor truly stood still (the red light's
wait, the jam's stops), the summed translation a method's poses made meanwhile (m;
``tools.family_suite.standstill_motion_m``), with each scene's static twin beside it.
"""

from __future__ import annotations

import math


def _text(value, spec: str = ".3f") -> str:
    return "n/a" if value is None or not math.isfinite(value) else format(value, spec)


def motion_table(results: list[dict], methods: list, sequences: list) -> str:
    """Markdown: a row per sequence, per method its end error / motion while standing still (m)."""
    header = ["sequence", *(f"{m.label}: end m / still m" for m in methods)]
    lines = ["| " + " | ".join(header) + " |", "|---|" + "---:|" * len(methods)]
    for s in sequences:
        cells = []
        for m in methods:
            r = next((x for x in results if x["method"] == m.name and x["sequence"] == s.id), None)
            if r is None:
                cells.append("")
            elif r["status"] != "ok" or r["figures"].get("diverged"):
                cells.append("failed" if r["status"] != "ok" else "diverged")
            else:
                f = r["figures"]
                still = f.get("standstill_motion_m")
                cells.append(f"{_text(f.get('end_error_m'))} / {'-' if still is None else _text(still)}")
        lines.append("| " + " | ".join([s.id, *cells]) + " |")
    return "\n".join(lines)


__all__ = ["motion_table"]
