"""The rejector study's perturbation levels and GCR's recall over what it judges.

Shared by the study (``rejector_study``, whose results are keyed by the labels)
and its figures (``plots``), so that neither imports the other's module.
"""

from __future__ import annotations


def level_label(level: tuple[float, float]) -> str:
    """(l_r deg, l_t m) -> the label results are keyed by, e.g. ``5 deg / 0.5 m``."""
    return f"{level[0]:g} deg / {level[1]:g} m"


def bounded_recall(gcr: dict, unbounded: dict | None) -> float | None:
    """GCR's recall over the true candidates whose source has a finite threshold (those it judges)."""
    if unbounded is None:
        return None
    judged = gcr["true"] - unbounded["kept_true"]
    return (gcr["kept_true"] - unbounded["kept_true"]) / judged if judged > 0 else None
