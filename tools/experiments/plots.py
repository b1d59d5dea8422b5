"""Every figure of the experiments and the demo (PNG, matplotlib's Agg renderer).

Matplotlib is imported inside each function (``salo --help`` and the odometry
never load it). Figures are built with ``matplotlib.figure.Figure`` directly,
never pyplot, so no GUI backend or global state is involved; each PNG is
written beside its final name and renamed, so a reader never sees half a file.
Units are in every axis label.
"""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np

METHOD_COLORS = {"ground truth": "black", "BL": "tab:blue", "NCF": "tab:orange", "SALO": "tab:green",
                 "KISS-ICP": "tab:purple", "default": "tab:red", "BL map": "tab:cyan", "NCF map": "tab:olive",
                 "SALO map": "tab:pink", "GenZ-ICP": "tab:brown", "small_gicp s2m": "tab:gray"}
# Widths and dashes differ so that methods whose tracks coincide stay visible under each other.
METHOD_STYLES = {"BL": ("-", 3.4), "NCF": ("--", 2.2), "SALO": ("-", 1.2), "KISS-ICP": (":", 2.2),
                 "default": ("-", 2.6), "GenZ-ICP": ("-.", 1.6), "small_gicp s2m": ((0, (1, 3)), 2.0)}
REJECTOR_COLORS = {"distance": "tab:blue", "gcr": "tab:green"}
TARGET_HATCH = {"filtered": "", "raw": "///", "map": "..."}
TARGET_LINES = {"filtered": "-", "raw": "--", "map": ":"}
# Log-scale plots show errors below this as this (exact zeros have no logarithm).
LOG_FLOOR_M = 1e-4


def save_png(fig, path: str | Path, dpi: int = 110) -> Path:
    """Render ``fig`` to PNG in memory and write it atomically (a reader never sees half a file)."""
    from simlidar.formats.atomic import atomic_write_bytes

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")  # never crop a legend or a label
    atomic_write_bytes(path, buf.getvalue())
    return Path(path)




def _level(level: dict) -> str:
    """The rejector study's label of a perturbation level (its results are keyed by it)."""
    from .levels import level_label

    return level_label((level["l_r_deg"], level["l_t_m"]))


def _plain_log_ticks(ax, which: str = "both") -> None:
    """Log-axis tick labels as plain numbers (0.5, 1, 2, 5) rather than powers of ten."""
    from matplotlib.ticker import FuncFormatter, LogLocator

    for name in ("x", "y") if which == "both" else (which,):
        axis = getattr(ax, f"{name}axis")
        axis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 3.0, 5.0)))
        axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        axis.set_minor_formatter(FuncFormatter(lambda v, _: ""))


def _figure(**kwargs):
    from matplotlib.figure import Figure

    return Figure(layout="constrained", **kwargs)


# ---------------------------------------------------------------- trajectories (Fig. 4)
def _view(gt: np.ndarray, square: bool) -> tuple[np.ndarray, np.ndarray]:
    """(2,) lower and upper x, y limits around the ground truth's track, m (a square, or its own shape)."""
    lo, hi = gt[:, :2, 3].min(axis=0), gt[:, :2, 3].max(axis=0)
    span = float(np.max(hi - lo))
    margin = max(3.0, 0.15 * span)
    lo, hi = lo - margin, hi + margin
    if square:
        centre, half = (lo + hi) / 2, float(np.max(hi - lo)) / 2
        return centre - half, centre + half
    # Not thinner than a third of the longer side: a straight road still shows its lateral error.
    centre, half = (lo + hi) / 2, np.maximum((hi - lo) / 2, float(np.max(hi - lo)) / 6)
    return centre - half, centre + half


def _draw_tracks(ax, gt: np.ndarray, est: dict, errs: dict | None, segment_length_m: float,
                 square: bool = True) -> None:
    ax.plot(gt[:, 0, 3], gt[:, 1, 3], color=METHOD_COLORS["ground truth"], lw=2.2, ls="--", label="ground truth",
            zorder=5)
    for name, poses in est.items():
        label = name
        if errs and name in errs and math.isfinite(errs[name][0]):
            mu, sd = errs[name]
            label = f"{name}: mu {mu:.2f}, sigma {sd:.2f} m/100 m"
        ls, lw = METHOD_STYLES.get(name, ("-", 1.4))
        ax.plot(poses[:, 0, 3], poses[:, 1, 3], color=METHOD_COLORS.get(name), ls=ls, lw=lw, label=label)
    ax.plot(gt[0, 0, 3], gt[0, 1, 3], "ks", ms=7, mfc="none", mew=1.5, label="start")
    # The view follows the ground truth (with a margin): a diverged estimate must not shrink it to a dot.
    lo, hi = _view(gt, square)
    outside = [name for name, poses in est.items()
               if np.any(poses[:, :2, 3] < lo) or np.any(poses[:, :2, 3] > hi)]
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal", adjustable="box")
    if outside:
        ax.text(0.99, 0.01, "leaves the view: " + ", ".join(outside), transform=ax.transAxes, ha="right",
                va="bottom", fontsize=8.5, color="0.25", bbox={"facecolor": "white", "alpha": 0.8, "edgecolor": "0.7"})
    ax.set_xlabel("x, m (first frame: forward)")
    ax.set_ylabel("y, m (first frame: left)")
    ax.grid(True, alpha=0.3)


def trajectory_plot(path, gt: np.ndarray, est: dict, errs: dict | None = None, title: str = "",
                    segment_length_m: float = 100.0) -> Path:
    """Top view of ground truth (N, 4, 4) and each method's poses (name -> (N, 4, 4)), in metres."""
    lo, hi = _view(gt, square=False)
    ratio = float((hi[1] - lo[1]) / (hi[0] - lo[0]))
    width = 9.0 if ratio <= 1 else max(7.0, 8.0 / ratio)  # wide enough for a two-column legend
    fig = _figure(figsize=(width, min(9.0, max(3.0, width * ratio)) + 1.6))
    ax = fig.subplots()
    _draw_tracks(ax, gt, est, errs, segment_length_m, square=False)
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=2, fontsize=9)
    _end_inset(ax, gt, est)
    note = "" if segment_length_m == 100.0 else f" ({segment_length_m:g} m segments)"
    ax.set_title((title or "trajectory, top view") + note)
    return save_png(fig, path)


def _end_inset(ax, gt: np.ndarray, est: dict) -> None:
    """A zoom on the end of the path, where the methods' drift shows (tracks overlap at full scale)."""
    from matplotlib.ticker import MaxNLocator

    end = gt[-1, :2, 3]
    errs = [float(np.linalg.norm(p[-1, :2, 3] - end)) for p in est.values()]
    half = max(1.0, 1.5 * max(errs, default=0.0))
    extent = float(np.max(np.ptp(gt[:, :2, 3], axis=0)))
    if extent < 8 * half:  # the ends are as far apart as the path is long: the full view shows it all
        return
    # The corner of the axes the ground truth crosses least (axes coordinates of its points).
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    u = (gt[:, 0, 3] - x0) / (x1 - x0)
    v = (gt[:, 1, 3] - y0) / (y1 - y0)
    size = 0.34
    corners = [(0.1, 0.05), (0.62, 0.05), (0.1, 0.6), (0.62, 0.6)]
    crossing = [np.sum((u > cx - 0.03) & (u < cx + size + 0.03) & (v > cy - 0.03) & (v < cy + size + 0.08))
                for cx, cy in corners]
    cx, cy = corners[int(np.argmin(crossing))]
    inset = ax.inset_axes([cx, cy, size, size])
    inset.plot(gt[:, 0, 3], gt[:, 1, 3], color="black", lw=2.0, ls="--")
    for name, poses in est.items():
        ls, lw = METHOD_STYLES.get(name, ("-", 1.4))
        inset.plot(poses[:, 0, 3], poses[:, 1, 3], color=METHOD_COLORS.get(name), ls=ls, lw=lw)
        inset.plot(poses[-1, 0, 3], poses[-1, 1, 3], "o", color=METHOD_COLORS.get(name), ms=5)
    inset.plot(end[0], end[1], "k*", ms=10)
    inset.set_xlim(end[0] - half, end[0] + half)
    inset.set_ylim(end[1] - half, end[1] + half)
    inset.set_aspect("equal", adjustable="box")
    inset.set_title(f"end of path, +-{half:.1f} m (star: truth)", fontsize=8)
    inset.tick_params(labelsize=7)
    inset.xaxis.set_major_locator(MaxNLocator(4))
    inset.yaxis.set_major_locator(MaxNLocator(4))
    inset.grid(True, alpha=0.3)
    ax.indicate_inset_zoom(inset, edgecolor="0.4")


def panel_label(i: int) -> str:
    """The i-th panel's letters, from 0: a, b, ..., z, aa, ab, ... (a grid of every sequence has more than 26)."""
    label = ""
    i += 1
    while i:
        i, r = divmod(i - 1, 26)
        label = chr(97 + r) + label
    return label


def trajectory_grid(path, tracks: list, segment_length_m: float = 100.0) -> Path:
    """All sequences side by side, as the paper's Fig. 4: tracks = [(name, gt, est, errs), ...]."""
    n = max(len(tracks), 1)
    cols = min(3, n)
    rows = math.ceil(n / cols)
    fig = _figure(figsize=(5.6 * cols, 5.0 * rows + 0.8))
    axes = np.atleast_1d(fig.subplots(rows, cols)).ravel()
    for i, (name, gt, est, errs) in enumerate(tracks):
        ax = axes[i]
        _draw_tracks(ax, gt, est, None, segment_length_m)
        parts = [f"{k} {v[0]:.2f}" for k, v in errs.items() if math.isfinite(v[0])]
        ax.set_title(f"{panel_label(i)}) {name}" + ("\nmu, m/100 m: " + ", ".join(parts) if parts else ""), fontsize=10)
    for ax in axes[len(tracks):]:
        ax.set_visible(False)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=len(labels), fontsize=10)
    fig.suptitle("Ground truth against every method, top view" +
                 ("" if segment_length_m == 100.0 else f" ({segment_length_m:g} m segments)"))
    return save_png(fig, path)


def error_bars(path, rows: list[dict], segment_length_m: float = 100.0) -> Path:
    """mu with sigma whiskers per sequence (and overall) and method, m per 100 m, on a log axis.

    A log axis, because one degenerate sequence (a tunnel) can be a hundred times
    worse than the rest; the lower whisker is clipped at 5 % of mu (a log axis has no 0).
    """
    seqs = list(dict.fromkeys(r["sequence"] for r in rows))
    methods = list(dict.fromkeys(r["method"] for r in rows))
    fig = _figure(figsize=(max(7.5, 1.3 * len(seqs) + 3), 4.8))
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


def position_error_plot(path, gt: np.ndarray, est: dict, distances_m: np.ndarray) -> Path:
    """Position error (m) of each method against the distance travelled (m)."""
    fig = _figure(figsize=(8.0, 4.2))
    ax = fig.subplots()
    for name, poses in est.items():
        err = np.linalg.norm(poses[:, :3, 3] - gt[:, :3, 3], axis=1)
        ls, lw = METHOD_STYLES.get(name, ("-", 1.5))
        ax.plot(distances_m, err, color=METHOD_COLORS.get(name), ls=ls, lw=lw, label=name)
    ax.set_xlabel("distance travelled along the ground truth, m")
    ax.set_ylabel("position error, m")
    ax.set_ylim(bottom=0)
    ax.grid(True, alpha=0.3)
    ax.legend()
    ax.set_title("Position error against ground truth (both start at the identity)")
    return save_png(fig, path)


def scan_preview(path, points: np.ndarray, rings: np.ndarray, n_rings: int, title: str = "",
                 half_width_m: float = 60.0) -> Path:
    """Top view of one scan (N, 3) coloured by ring (N,), within +-half_width_m of the sensor."""
    fig = _figure(figsize=(8.0, 7.2))
    ax = fig.subplots()
    keep = (np.abs(points[:, 0]) < half_width_m) & (np.abs(points[:, 1]) < half_width_m)
    sc = ax.scatter(points[keep, 0], points[keep, 1], c=rings[keep], s=0.5, cmap="turbo", vmin=0,
                    vmax=max(n_rings - 1, 1), rasterized=True, linewidths=0)
    ax.plot(0, 0, marker="^", color="black", ms=9, label="sensor (x forward)")
    ax.set_aspect("equal")
    ax.set_xlim(-half_width_m, half_width_m)
    ax.set_ylim(-half_width_m, half_width_m)
    ax.set_xlabel("x, m (forward)")
    ax.set_ylabel("y, m (left)")
    ax.legend(loc="upper right")
    fig.colorbar(sc, ax=ax, label="ring (0 = lowest beam)", shrink=0.85)
    ax.set_title(title or "one scan, top view")
    return save_png(fig, path, dpi=130)


# ---------------------------------------------------------------- rejector study (Fig. 3)
def rejector_boxplot(path, registrations: list[dict], params: dict) -> Path:
    """Translation error after ICP per noise level: a box per (rejector, target), and the initial error."""
    from matplotlib.patches import Patch

    levels = [_level(lv) for lv in params["levels"]]
    targets = params["targets"]
    groups = [(rej, t) for t in targets for rej in ("distance", "gcr")]
    fig = _figure(figsize=(max(8.0, (0.45 * len(groups) + 0.5) * len(levels) + 2), 5.4))
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
    fig = _figure(figsize=(max(8.0, 1.5 * len(cats) + 3), 7.0))
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
    fig = _figure(figsize=(6.0 * len(targets), 8.6))
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
    fig = _figure(figsize=(6.2 * len(models), 8.6))
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
        _plain_log_ticks(top)
        _plain_log_ticks(bottom, "x")
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
    fig = _figure(figsize=(4.2 * len(noises) + 1, 7.2))
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
        _plain_log_ticks(axes[1, j])
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


def family_error_plot(path, results: list[dict], methods: tuple[str, ...], label, failure_pct: float) -> Path:
    """KITTI t_err per scene family and method, one panel per data kind (log scale).

    results: the generalisation suite's per-sequence results; a bar is the mean over the
    family's sequences, each dot one sequence; the dashed line is the failure threshold.
    """
    kinds = sorted({r["sequence"]["kind"] for r in results})
    families = sorted({r["sequence"]["family"] for r in results})
    fig = _figure(figsize=(max(8.0, 1.25 * len(families) * max(1, len(methods)) / 3), 3.6 * len(kinds) + 1.0))
    axes = np.atleast_1d(fig.subplots(len(kinds), 1, sharex=True))
    width = 0.8 / max(len(methods), 1)
    for ax, kind in zip(axes, kinds, strict=True):
        for j, m in enumerate(methods):
            name = label(m)
            xs, means = [], []
            for i, fam in enumerate(families):
                vals = [r["methods"][m]["t_err_pct"] for r in results
                        if r["sequence"]["family"] == fam and r["sequence"]["kind"] == kind
                        and r["methods"].get(m, {}).get("ok")]
                vals = np.clip(np.nan_to_num(np.array(vals, dtype=float), nan=1e3, posinf=1e3), 1e-3, 1e3)
                x = i - 0.4 + (j + 0.5) * width
                if len(vals):
                    xs.append(x)
                    means.append(float(np.mean(vals)))
                    ax.plot(np.full(len(vals), x), vals, "o", ms=3, color="black", alpha=0.6, zorder=3)
            ax.bar(xs, means, width=width * 0.95, color=METHOD_COLORS.get(name), label=name, alpha=0.85)
        ax.axhline(failure_pct, color="0.3", ls="--", lw=1)
        ax.set_yscale("log")
        _plain_log_ticks(ax, "y")
        ax.set_ylabel("KITTI t_err, %")
        ax.set_title(f"as {kind}: bars = mean over the family's sequences, dots = sequences, dashed = failure")
        ax.grid(True, axis="y", alpha=0.3)
    axes[-1].set_xticks(range(len(families)), families)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=min(len(labels), 5), fontsize=9)
    return save_png(fig, path)
