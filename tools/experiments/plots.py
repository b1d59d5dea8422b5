"""The experiments' own figures (PNG, matplotlib's Agg renderer): error bars per sequence, the rejector
and NCF studies, the generalisation suite per family.

The figures others share (trajectories, position error, a scan, the colours of the methods, writing a
PNG) are ``tools.plotting``'s; as there, matplotlib is imported inside each function, figures are built
without pyplot, and units are in every axis label.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from tools.plotting import LOG_FLOOR_M, METHOD_COLORS, new_figure, plain_log_ticks, save_png

REJECTOR_COLORS = {"distance": "tab:blue", "gcr": "tab:green"}
TARGET_HATCH = {"filtered": "", "raw": "///", "map": "..."}
TARGET_LINES = {"filtered": "-", "raw": "--", "map": ":"}


def _level(level: dict) -> str:
    """The rejector study's label of a perturbation level (its results are keyed by it)."""
    from .levels import level_label

    return level_label((level["l_r_deg"], level["l_t_m"]))


def error_bars(path, rows: list[dict], segment_length_m: float = 100.0) -> Path:
    """mu with sigma whiskers per sequence (and overall) and method, m per 100 m, on a log axis.

    A log axis, because one degenerate sequence (a tunnel) can be a hundred times
    worse than the rest; the lower whisker is clipped at 5 % of mu (a log axis has no 0).
    """
    seqs = list(dict.fromkeys(r["sequence"] for r in rows))
    methods = list(dict.fromkeys(r["method"] for r in rows))
    fig = new_figure(figsize=(max(7.5, 1.3 * len(seqs) + 3), 4.8))
    ax = fig.subplots()
    width = 0.7 / max(len(methods), 1)
    x = np.arange(len(seqs))
    for j, m in enumerate(methods):
        get = {(r["sequence"]): r for r in rows if r["method"] == m}
        mu = np.array([_num(get.get(s, {}).get("mu_m_per_100m")) for s in seqs])
        sd = np.array([_num(get.get(s, {}).get("sigma_m_per_100m")) for s in seqs])
        lower = np.minimum(sd, 0.95 * mu)
        ax.errorbar(x + (j - (len(methods) - 1) / 2) * width, mu, yerr=[lower, sd], fmt="o", ms=7, capsize=4,
                    color=METHOD_COLORS.get(m), label=m)
    ax.set_yscale("log")
    ax.set_xticks(x, seqs)
    for k in range(len(seqs) - 1):
        ax.axvline(k + 0.5, color="0.85", lw=0.8)
    ax.set_ylabel("translational error, m per 100 m (log)")
    ax.set_xlabel("sequence")
    ax.grid(True, axis="y", which="both", alpha=0.3)
    ax.legend(title="dot: mu, whiskers: +-sigma", fontsize=9)
    ax.set_title(f"Relative positioning error of {segment_length_m:g} m segments, per sequence and pooled")
    return save_png(fig, path)


def _num(v) -> float:
    return float("nan") if v is None else float(v)


# ---------------------------------------------------------------- rejector study (Fig. 3)
def rejector_boxplot(path, registrations: list[dict], params: dict) -> Path:
    """Translation error after ICP per noise level: a box per (rejector, target), and the initial error."""
    from matplotlib.patches import Patch

    levels = [_level(lv) for lv in params["levels"]]
    targets = params["targets"]
    groups = [(rej, t) for t in targets for rej in ("distance", "gcr")]
    fig = new_figure(figsize=(max(8.0, (0.45 * len(groups) + 0.5) * len(levels) + 2), 5.4))
    ax = fig.subplots()
    slots = len(groups) + 1
    width = 0.8 / slots
    for i, level in enumerate(levels):
        rows = [r for r in registrations if r["level"] == level]
        init = [max(r["initial_t_err_m"], LOG_FLOOR_M) for r in rows if r["rejector"] == "distance"
                and r["target"] == targets[0]]
        data = [init] + [[max(r["t_err_m"], LOG_FLOOR_M) for r in rows if r["rejector"] == rej and r["target"] == t]
                         for rej, t in groups]
        pos = i + (np.arange(slots) - (slots - 1) / 2) * width
        for j, d in enumerate(data):
            if not d or (j == 0 and max(d) <= LOG_FLOOR_M):  # no initial error at the zero level
                continue
            bp = ax.boxplot([d], positions=[pos[j]], widths=width * 0.85, patch_artist=True, showfliers=True,
                            flierprops={"markersize": 2.5, "alpha": 0.5})
            box = bp["boxes"][0]
            if j == 0:
                box.set_facecolor("0.85")
            else:
                rej, t = groups[j - 1]
                box.set_facecolor(REJECTOR_COLORS[rej])
                box.set_alpha(0.8)
                box.set_hatch(TARGET_HATCH.get(t, ""))
            for med in bp["medians"]:
                med.set_color("black")
    ax.set_yscale("log")
    ax.set_xticks(range(len(levels)), [f"l_r = {lv['l_r_deg']:g} deg\nl_t = {lv['l_t_m']:g} m"
                                       for lv in params["levels"]])
    ax.set_xlabel("initial-guess noise level")
    ax.set_ylabel(f"translation error, m (log; below {LOG_FLOOR_M:g} m shown at {LOG_FLOOR_M:g})")
    ax.grid(True, axis="y", which="both", alpha=0.25)
    handles = [Patch(facecolor="0.85", edgecolor="black", label="initial guess")]
    handles += [Patch(facecolor=REJECTOR_COLORS[rej], hatch=TARGET_HATCH.get(t, ""), edgecolor="black", alpha=0.8,
                      label=f"{'GCR' if rej == 'gcr' else 'distance'} rejector, {t} target") for rej, t in groups]
    ax.legend(handles=handles, loc="upper left", fontsize=9)
    n = len({r["pair"] for r in registrations})
    ax.set_title(f"Translation error after ICP, {n} scan pairs per level (cf. SALO Fig. 3)")
    return save_png(fig, path)


def rejector_precision_recall(path, pr_summary: list[dict], params: dict) -> Path:
    """Precision and recall of the distance rejector and GCR against the true correspondences.

    Where some candidates' sources have no finite GCR threshold (GCR keeps them unjudged:
    against a map, no plane match within the bound at the first iteration), the recall
    panel also shows GCR's recall over the candidates it judges (thin line, triangles).
    """
    from .levels import bounded_recall

    cats = ["true pose"] + [_level(lv) for lv in params["levels"]]
    fig = new_figure(figsize=(max(8.0, 1.5 * len(cats) + 3), 7.0))
    axes = fig.subplots(2, 1, sharex=True)

    def row_of(c: str, t: str, rej: str) -> dict | None:
        stage = "true pose" if c == "true pose" else "initial guess"
        return next((r for r in pr_summary if r["stage"] == stage and r["level"] == c and r["target"] == t
                     and r["rejector"] == rej), None)

    for ax, key in zip(axes, ("precision", "recall"), strict=True):
        for t in params["targets"]:
            for rej in ("distance", "gcr"):
                y = []
                for c in cats:
                    row = row_of(c, t, rej)
                    v = None if row is None else row[key]
                    y.append(np.nan if v is None else v)
                ax.plot(range(len(cats)), y, TARGET_LINES.get(t, "-"), marker="o", color=REJECTOR_COLORS[rej],
                        label=f"{'GCR' if rej == 'gcr' else 'distance'}, {t} target")
            if key == "recall":
                free = [row_of(c, t, "gcr_unbounded") for c in cats]
                if any(f is not None and f["kept"] > 0 for f in free):
                    y = []
                    for c, f in zip(cats, free, strict=True):
                        g = row_of(c, t, "gcr")
                        v = None if g is None else bounded_recall(g, f)
                        y.append(np.nan if v is None else v)
                    ax.plot(range(len(cats)), y, TARGET_LINES.get(t, "-"), marker="v", lw=1.0,
                            color=REJECTOR_COLORS["gcr"], alpha=0.6,
                            label=f"GCR, {t} target: over the candidates with a finite threshold")
        ax.set_ylabel(f"{key} (0-1)")
        ax.set_ylim(-0.02, 1.02)
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=9, ncol=len(params["targets"]), loc="lower left")
    axes[1].legend(fontsize=8.5, loc="lower left")
    axes[1].set_xticks(range(len(cats)), ["at the\ntrue pose"] +
                       ["initial guess\n" + _level(lv) for lv in params["levels"]])
    axes[1].set_xlabel("where the nearest-neighbour candidates are taken")
    axes[0].set_title("Rejectors against the true correspondences: precision = kept true / kept, "
                      "recall = kept true / true", fontsize=10)
    return save_png(fig, path)


def match_distance_histogram(path, samples: dict, head_on_deg: float = 45.0) -> Path:
    """Per target: distances of true matches at the true pose against the GCR thresholds of their sources, m.

    Top row: every true match; bottom row: sources seen within ``head_on_deg`` of
    the surface normal, where the threshold is the sensor's sampling spacing.
    """
    targets = list(samples)
    fig = new_figure(figsize=(6.0 * len(targets), 8.6))
    axes = np.array(fig.subplots(2, len(targets), sharey="row", sharex=True)).reshape(2, len(targets))
    top = 3.0
    bins = np.logspace(-3, math.log10(top), 56)
    for col, t in enumerate(targets):
        d_all = np.asarray(samples[t]["distance_m"], dtype=float)
        thr_all = np.asarray(samples[t]["gcr_threshold_m"], dtype=float)
        inc = np.asarray(samples[t].get("incidence_deg", np.zeros(len(d_all))), dtype=float)
        for row, (sel, what) in enumerate(((np.ones(len(d_all), bool), "all true matches"),
                                           (inc < head_on_deg, f"sources within {head_on_deg:g} deg of head-on"))):
            ax = axes[row, col]
            d, thr = d_all[sel], thr_all[sel]
            if len(d):
                # Weights 1/n: bar heights are shares of the matches, comparable across log-spaced bins.
                w = np.full(len(d), 1 / len(d))
                ax.hist(np.clip(d, bins[0], top * 0.999), bins=bins, weights=w, alpha=0.6, color="tab:red",
                        label=f"distance to the nearest target point (median {np.median(d) * 100:.1f} cm)")
                ax.hist(np.clip(thr, bins[0], top * 0.999), bins=bins, weights=w, alpha=0.6, color="tab:green",
                        label=f"GCR threshold max d_kl (median {np.median(thr) * 100:.1f} cm)")
                ax.set_title(f"{t} target, {what}:\nGCR keeps {100 * float(np.mean(d < thr)):.1f} % of "
                             f"{len(d)} sampled true matches", fontsize=10)
            ax.set_xscale("log")
            ax.grid(True, alpha=0.3)
            ax.legend(loc="upper left", fontsize=8.5)
        axes[1, col].set_xlabel(f"distance, m (log; above {top:g} m, e.g. grazing incidence, in the last bin)")
    for row in range(2):
        axes[row, 0].set_ylabel("share of the true matches per bin")
    fig.suptitle("True correspondences at the true pose: match distance against the GCR threshold of the same "
                 "source point")
    return save_png(fig, path)


# ---------------------------------------------------------------- NCF study
def ncf_calibration(path, calibration: list[dict], min_count: int = 20) -> Path:
    """Per model: actual against predicted RMS tilt of the normal (deg), and the share inside the 95 % bound."""
    models = list(dict.fromkeys(r["model"] for r in calibration))
    noises = sorted({r["noise_std_m"] for r in calibration})
    cmap = _noise_colors(noises)
    fig = new_figure(figsize=(6.2 * len(models), 8.6))
    axes = np.array(fig.subplots(2, len(models), sharex=True, sharey="row", height_ratios=[1.6, 1])
                    ).reshape(2, len(models))
    lo, hi = 0.2, 50.0
    for col, model in enumerate(models):
        top, bottom = axes[0, col], axes[1, col]
        top.plot([lo, hi], [lo, hi], color="0.4", lw=1, ls=":", label="calibrated (actual = predicted)")
        bottom.axhline(0.95, color="0.4", lw=1, ls=":", label="calibrated: 0.95")
        for noise in noises:
            for subset, ls, alpha in (("single-surface", "-", 1.0), ("all", "--", 0.5)):
                rows = [r for r in calibration if r["model"] == model and r["noise_std_m"] == noise
                        and r["subset"] == subset and r["count"] >= min_count
                        and math.isfinite(_num(r["predicted_rms_deg"]))]
                if not rows:
                    continue
                x = [r["predicted_rms_deg"] for r in rows]
                label = f"{1000 * noise:g} mm, {subset} points"
                top.plot(x, [r["actual_rms_deg"] for r in rows], ls, marker="o", ms=4, color=cmap[noise],
                         alpha=alpha, label=label)
                bottom.plot(x, [_num(r["within_95"]) for r in rows], ls, marker="o", ms=4, color=cmap[noise],
                            alpha=alpha)
        top.set_xscale("log")
        top.set_yscale("log")
        top.set_xlim(lo, hi)
        top.set_ylim(lo, hi)
        plain_log_ticks(top)
        plain_log_ticks(bottom, "x")
        top.set_title(f"{model} noise model")
        top.grid(True, which="both", alpha=0.25)
        top.legend(fontsize=8, loc="upper left")
        bottom.set_ylim(0, 1.02)
        bottom.set_xlabel("predicted RMS tilt of the normal in the bin, deg (log)")
        bottom.grid(True, which="both", alpha=0.25)
        bottom.legend(fontsize=8, loc="lower right")
    axes[0, 0].set_ylabel("actual RMS angle to the true normal, deg")
    axes[1, 0].set_ylabel("share with Mahalanobis^2 < 5.99 (0-1)")
    fig.suptitle(f"NCF calibration: points binned by predicted max std (bins with >= {min_count} points)")
    return save_png(fig, path)


def ncf_ctau(path, ctau: list[dict], default_c_tau_deg: float | None = None) -> Path:
    """Kept share and true normal error of kept / rejected points against c_tau, per noise level.

    ``default_c_tau_deg``: the odometry's configured c_tau, marked by a dotted line.
    """
    noises = sorted({r["noise_std_m"] for r in ctau})
    models = list(dict.fromkeys(r["model"] for r in ctau))
    colors = {"range": "tab:green", "isotropic": "tab:blue"}
    fig = new_figure(figsize=(4.2 * len(noises) + 1, 7.2))
    axes = np.array(fig.subplots(2, len(noises), sharex=True, sharey="row")).reshape(2, len(noises))
    for j, noise in enumerate(noises):
        for model in models:
            rows = sorted((r for r in ctau if r["model"] == model and r["noise_std_m"] == noise),
                          key=lambda r: r["c_tau_deg"])
            c = [r["c_tau_deg"] for r in rows]
            axes[0, j].plot(c, [r["kept_fraction"] for r in rows], "-o", ms=3, color=colors.get(model), label=model)
            axes[1, j].plot(c, [np.nan if r["kept_error_median_deg"] is None else r["kept_error_median_deg"]
                                for r in rows], "-o", ms=3, color=colors.get(model), label=f"{model}: kept")
            axes[1, j].plot(c, [np.nan if r["rejected_error_median_deg"] is None else r["rejected_error_median_deg"]
                                for r in rows], "--s", ms=3, color=colors.get(model), label=f"{model}: rejected")
        axes[0, j].set_title(f"range noise {1000 * noise:g} mm")
        axes[1, j].set_xlabel("c_tau as a 1-sigma angle, deg (log)")
        axes[0, j].set_xscale("log")
        axes[1, j].set_yscale("log")
        plain_log_ticks(axes[1, j])
        for ax in axes[:, j]:
            ax.grid(True, which="both", alpha=0.25)
        if default_c_tau_deg:
            for ax in axes[:, j]:
                ax.axvline(default_c_tau_deg, color="0.5", lw=1, ls=":")
    axes[0, 0].set_ylabel("share of points kept (0-1)")
    axes[0, 0].set_ylim(0, 1.02)
    axes[1, 0].set_ylabel("median angle to the true normal, deg")
    axes[0, 0].legend(fontsize=9, title="noise model")
    axes[1, 0].legend(fontsize=8)
    fig.suptitle("NCF as c_tau varies" + (f" (dotted: the configured {default_c_tau_deg:g} deg)"
                                          if default_c_tau_deg else ""))
    return save_png(fig, path)


def _noise_colors(noises) -> dict:
    """A distinct, dark-enough colour per noise level (sequential maps fade to white at one end)."""
    palette = ["#1b4f9c", "#d95f02", "#1b9e77", "#7570b3", "#e7298a", "#66a61e", "#a6761d", "#444444"]
    return {v: palette[i % len(palette)] for i, v in enumerate(noises)}


def family_error_plot(path, results: list[dict], methods: tuple[str, ...], label, failure_pct: float,
                      note: str = "") -> Path:
    """KITTI t_err per scene family and method, one panel per data kind (log scale).

    results: the generalisation suite's per-sequence results; a bar is the mean over the
    family's sequences, each dot one sequence; the dashed line is the failure threshold.
    note: a line above the panels (what the run changed, what a bar pools).
    """
    kinds = sorted({r["sequence"]["kind"] for r in results})
    families = sorted({r["sequence"]["family"] for r in results})
    fig = new_figure(figsize=(max(8.0, 1.25 * len(families) * max(1, len(methods)) / 3), 3.6 * len(kinds) + 1.0))
    axes = np.atleast_1d(fig.subplots(len(kinds), 1, sharex=True))
    width = 0.8 / max(len(methods), 1)
    for ax, kind in zip(axes, kinds, strict=True):
        for j, m in enumerate(methods):
            name = label(m)
            xs, means = [], []
            for i, fam in enumerate(families):
                runs = [r["methods"][m] for r in results
                        if r["sequence"]["family"] == fam and r["sequence"]["kind"] == kind
                        and r["methods"].get(m, {}).get("ok")]
                # a diverged run at the top; a path shorter than every segment has no t_err: no dot
                vals = [1e3 if x.get("diverged") else x["t_err_pct"] for x in runs]
                vals = np.array([v for v in vals if v is not None and not np.isnan(v)], dtype=float)
                vals = np.clip(np.nan_to_num(vals, posinf=1e3), 1e-3, 1e3)
                x = i - 0.4 + (j + 0.5) * width
                if len(vals):
                    xs.append(x)
                    means.append(float(np.mean(vals)))
                    ax.plot(np.full(len(vals), x), vals, "o", ms=3, color="black", alpha=0.6, zorder=3)
            ax.bar(xs, means, width=width * 0.95, color=METHOD_COLORS.get(name), label=name, alpha=0.85)
        ax.axhline(failure_pct, color="0.3", ls="--", lw=1)
        ax.set_yscale("log")
        plain_log_ticks(ax, "y")
        ax.set_ylabel("KITTI t_err, %")
        ax.set_title(f"as {kind}: bars = mean over the family's sequences, dots = sequences, dashed = failure")
        ax.grid(True, axis="y", alpha=0.3)
    axes[-1].set_xticks(range(len(families)), families)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=min(len(labels), 5), fontsize=9)
    if note:
        fig.suptitle(note, fontsize=9)
    return save_png(fig, path)
