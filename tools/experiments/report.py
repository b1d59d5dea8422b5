"""One page from a results folder: every run's summary, tables and figures.

``RESULTS_DIR`` is a run folder (it holds ``run.json``) or a folder of run
folders (searched two levels deep). For each run the page gives where it
came from (command, version, git commit, date, duration) and the run's
``summary.md`` (its tables and figures in order), then any PNG of the run
the summary does not show.

- HTML: the Markdown is rendered by ``tools.html_page``, a small converter that
  knows exactly what the experiments write (headings, paragraphs, bullet lists,
  pipe tables, images, bold, inline code); images are embedded as base64 data
  URIs, so the file is self-contained and can be mailed or archived alone.
- Markdown: the summaries concatenated, image links rewritten relative to
  the report file (self-contained together with the results folder).
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

from tools.html_page import MARKDOWN_IMAGE, html_page
from tools.records import RUN_FILE, SUMMARY_FILE


class ReportError(ValueError):
    """The folder holds no run to report; the message says what was looked for."""


def find_runs(results_dir: str | Path) -> list[Path]:
    """Run folders (holding ``run.json``) at or up to two levels under ``results_dir``, sorted."""
    root = Path(results_dir)
    if not root.is_dir():
        raise ReportError(f"{root}: not a folder")
    if (root / RUN_FILE).is_file():
        return [root]
    runs = sorted({p.parent for p in [*root.glob(f"*/{RUN_FILE}"), *root.glob(f"*/*/{RUN_FILE}")]})
    if not runs:
        raise ReportError(f"{root}: no run folder here (a run folder holds {RUN_FILE}; run `salo experiment ...`)")
    return runs


def _provenance(run_dir: Path) -> tuple[dict, str]:
    info = json.loads((run_dir / RUN_FILE).read_text())
    git = info.get("git") or {}
    commit = git.get("commit", "")[:12] + (" (uncommitted changes)" if git.get("dirty") else "") if git else "n/a"
    lines = [
        f"- command: `{' '.join(info.get('command', []))}`",
        f"- salo-bench {info.get('version', '?')}, git {commit}, Python {info.get('python', '?')}, "
        f"numpy {info.get('numpy', '?')}",
        f"- started {info.get('started', '?')}, {info.get('seconds', '?')} s, status {info.get('status', '?')}",
    ]
    return info, "\n".join(lines) + "\n"


def _run_markdown(run_dir: Path, link_base: Path) -> str:
    """One run's section, image links relative to ``link_base``."""
    info, prov = _provenance(run_dir)
    summary = (run_dir / SUMMARY_FILE).read_text() if (run_dir / SUMMARY_FILE).is_file() else ""
    shown = set()

    def relink(m: re.Match) -> str:
        target = (run_dir / m.group(2)).resolve()
        shown.add(target)
        return f"![{m.group(1)}]({Path(os.path.relpath(target, link_base.resolve())).as_posix()})"

    body = MARKDOWN_IMAGE.sub(relink, summary)
    # The summary's first heading names the experiment; the provenance goes right under it.
    head, sep, rest = body.partition("\n")
    if not head.startswith("# "):
        head, rest = f"# {info.get('experiment', run_dir.name)}: {run_dir.name}", body
    parts = [head.replace("# ", "## ", 1) + f" [{run_dir.name}]", "", prov, _demote(rest if sep or rest else "")]
    others = sorted(p for p in run_dir.rglob("*.png") if p.resolve() not in shown and not p.name.startswith("."))
    if others:
        parts += ["", "### Other figures", ""]
        parts += [f"![{p.stem}]({Path(os.path.relpath(p.resolve(), link_base.resolve())).as_posix()})\n"
                  for p in others]
    if not summary:
        parts.insert(3, f"(no {SUMMARY_FILE} in {run_dir})\n")
    return "\n".join(parts)


def _demote(markdown: str) -> str:
    """Headings one level down (the report's own title is the only level-1 heading)."""
    return re.sub(r"^(#{1,5}) ", lambda m: "#" + m.group(1) + " ", markdown, flags=re.M)


def report_markdown(results_dir: str | Path, out_file: str | Path) -> str:
    runs = find_runs(results_dir)
    base = Path(out_file).parent
    parts = [f"# salo report: {Path(results_dir)}", ""]
    parts += [_run_markdown(r, base) for r in runs]
    return "\n".join(parts) + "\n"


def report_html(results_dir: str | Path, out_file: str | Path) -> str:
    return html_page(report_markdown(results_dir, out_file), f"salo report: {results_dir}", Path(out_file).parent)


def write_report(results_dir: str | Path, out_file: str | Path, fmt: str = "html") -> Path:
    """Write the page (``fmt`` "html" or "md") and return its path."""
    from simlidar.formats.atomic import atomic_write_text

    out = Path(out_file)
    out.parent.mkdir(parents=True, exist_ok=True)
    if fmt == "html":
        text = report_html(results_dir, out)
    elif fmt == "md":
        text = report_markdown(results_dir, out)
    else:
        raise ReportError(f"unknown report format {fmt!r} (html or md)")
    atomic_write_text(out, text)
    return out
