"""A sweep's summary: a table of means over seeds, and error-against-noise plots per scene.

Rows are grouped by (scene, sensor, noise level, variant); the seeds of a
group are the repetitions. Means are over the group's successful runs; a
figure that no run of the group has (e.g. the KITTI error of a sequence
shorter than 100 m) is left empty.
"""

from __future__ import annotations

import csv
import io
import math
from collections import defaultdict
from pathlib import Path

from simlidar.formats.atomic import atomic_write_text
from tools.plotting import save_png

GROUP_COLUMNS = ("scene", "sensor", "noise_std_m", "variant")
SUMMARY_METRICS = ("t_err_pct", "r_err_deg_per_100m", "t100_mean_m", "ate_aligned_rmse_m", "rpe_t_rmse_m",
                   "rpe_r_rmse_deg", "frames_per_s")
# The two panels of a scene's plot: the KITTI drift if the sequences are long enough, and the
# per-frame error that every sequence has.
PLOT_METRICS = (("t_err_pct", "KITTI translational error (%)", "ate_aligned_rmse_m", "ATE after alignment (m)"),
                ("rpe_t_rmse_m", "frame-to-frame translation error, RMSE (m)", None, None))


def _finite(values) -> list[float]:
    return [float(v) for v in values if isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)]


def _mean(values) -> float | None:
    v = _finite(values)
    return sum(v) / len(v) if v else None


def _std(values) -> float | None:
    v = _finite(values)
    if len(v) < 2:
        return None
    m = sum(v) / len(v)
    return math.sqrt(sum((x - m) ** 2 for x in v) / (len(v) - 1))


def summarize(rows: list[dict]) -> list[dict]:
    """One row per (scene, sensor, noise_std_m, variant), in first-seen order: ``runs``, ``failed``,
    ``seeds`` and the mean over successful runs of each of ``SUMMARY_METRICS`` (plus ``t_err_pct_std``,
    the sample std over seeds)."""
    groups: dict[tuple, list[dict]] = defaultdict(list)
    for row in rows:
        groups[tuple(row[c] for c in GROUP_COLUMNS)].append(row)
    out = []
    for key, members in groups.items():
        ok = [r for r in members if r["status"] == "ok"]
        entry = dict(zip(GROUP_COLUMNS, key, strict=True))
        entry.update(runs=len(members), failed=len(members) - len(ok), seeds=len({r["seed"] for r in ok}))
        for m in SUMMARY_METRICS:
            entry[m] = _mean(r[m] for r in ok)
        entry["t_err_pct_std"] = _std(r["t_err_pct"] for r in ok)
        out.append(entry)
    return out


def _fmt(value) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def format_markdown(summary: list[dict]) -> str:
    """The summary as a Markdown table (4 significant digits)."""
    if not summary:
        return "(no runs)\n"
    cols = list(summary[0])
    lines = ["| " + " | ".join(cols) + " |", "|" + "|".join("---" for _ in cols) + "|"]
    lines += ["| " + " | ".join(_fmt(s[c]) for c in cols) + " |" for s in summary]
    return "\n".join(lines) + "\n"


def format_csv(summary: list[dict]) -> str:
    buf = io.StringIO()
    if summary:
        w = csv.DictWriter(buf, fieldnames=list(summary[0]), lineterminator="\n")
        w.writeheader()
        w.writerows({k: ("" if v is None else v) for k, v in s.items()} for s in summary)
    return buf.getvalue()


def plot_scene(rows: list[dict], scene: str, path: Path) -> Path:
    """Error against noise level for one scene: a line per variant (and sensor, if several), the mean
    over seeds with the seeds' min..max as error bars and each seed as a dot. Two panels (see
    ``PLOT_METRICS``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [r for r in rows if r["scene"] == scene and r["status"] == "ok"]
    several_sensors = len({r["sensor"] for r in rows}) > 1
    fig, axes = plt.subplots(1, len(PLOT_METRICS), figsize=(6 * len(PLOT_METRICS), 4.2), squeeze=False)
    for ax, (metric, label, fallback, fallback_label) in zip(axes[0], PLOT_METRICS, strict=True):
        if fallback is not None and not _finite(r[metric] for r in rows):
            metric, label = fallback, fallback_label  # sequences too short for 100 m segments
        lines: dict[str, dict[float, list[float]]] = defaultdict(lambda: defaultdict(list))
        for r in rows:
            name = f"{r['variant']} / {Path(str(r['sensor'])).stem}" if several_sensors else r["variant"]
            if _finite([r[metric]]):
                lines[name][float(r["noise_std_m"])].append(float(r[metric]))
        # Noise levels as evenly spaced categories (a lone level still gets a readable axis),
        # each line shifted a little so that overlapping min..max bars stay apart.
        levels = sorted({n for by_noise in lines.values() for n in by_noise})
        slot = {n: i for i, n in enumerate(levels)}
        for k, (name, by_noise) in enumerate(lines.items()):
            shift = (k - (len(lines) - 1) / 2) * min(0.12, 0.6 / max(len(lines), 1))
            noise = sorted(by_noise)
            x = [slot[n] + shift for n in noise]
            y = [sum(by_noise[n]) / len(by_noise[n]) for n in noise]
            lo = [yi - min(by_noise[n]) for n, yi in zip(noise, y, strict=True)]
            hi = [max(by_noise[n]) - yi for n, yi in zip(noise, y, strict=True)]
            bar = ax.errorbar(x, y, yerr=[lo, hi], marker="o", capsize=3, label=name)
            seeds_x = [xi for xi, n in zip(x, noise, strict=True) for _ in by_noise[n]]
            seeds_y = [v for n in noise for v in by_noise[n]]
            ax.plot(seeds_x, seeds_y, ".", color=bar[0].get_color(), alpha=0.4, markersize=5)
        ax.set_xticks(range(len(levels)), [f"{1000 * n:g} mm" for n in levels])
        ax.set_xlim(-0.5, len(levels) - 0.5)
        ax.set_xlabel("range noise std")
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
        if lines:
            ax.legend(fontsize="small")
        else:
            ax.text(0.5, 0.5, "no successful runs", ha="center", va="center", transform=ax.transAxes)
    fig.suptitle(f"{scene}: error against range noise (mean over seeds, bars: min..max, dots: seeds)")
    fig.tight_layout()
    try:
        return save_png(fig, path)
    finally:
        plt.close(fig)


def write_report(rows: list[dict], out_dir: str | Path) -> dict[str, Path]:
    """summary.csv, summary.md and plots/<scene>.png under ``out_dir``; returns their paths by name."""
    out_dir = Path(out_dir)
    summary = summarize(rows)
    outputs = {"summary_csv": out_dir / "summary.csv", "summary_md": out_dir / "summary.md"}
    atomic_write_text(outputs["summary_csv"], format_csv(summary))
    atomic_write_text(outputs["summary_md"], format_markdown(summary))
    for scene in dict.fromkeys(r["scene"] for r in rows):
        outputs[f"plot_{scene}"] = plot_scene(rows, scene, out_dir / "plots" / f"{scene}.png")
    return outputs


__all__ = ["format_markdown", "plot_scene", "summarize", "write_report"]
