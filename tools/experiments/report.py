"""One page from a results folder: every run's summary, tables and figures.

``RESULTS_DIR`` is a run folder (it holds ``run.json``) or a folder of run
folders (searched two levels deep). For each run the page gives where it
came from (command, version, git commit, date, duration) and the run's
``summary.md`` (its tables and figures in order), then any PNG of the run
the summary does not show.

- HTML: the Markdown is rendered by a small converter that knows exactly what
  the experiments write (headings, paragraphs, bullet lists, pipe tables,
  images, bold, inline code); images are embedded as base64 data URIs, so
  the file is self-contained and can be mailed or archived alone.
- Markdown: the summaries concatenated, image links rewritten relative to
  the report file (self-contained together with the results folder).
"""

from __future__ import annotations

import base64
import html
import json
import os
import re
from pathlib import Path

from .records import RUN_FILE, SUMMARY_FILE

_IMAGE = re.compile(r"!\[([^\]]*)\]\(([^)\s]+)\)")


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

    body = _IMAGE.sub(relink, summary)
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


# ---------------------------------------------------------------- Markdown -> HTML
def _inline(text: str, img) -> str:
    """Inline Markdown (images, links, bold, code) to HTML; ``img(src, alt)`` renders an image."""
    out, pos = [], 0
    for m in _IMAGE.finditer(text):
        out.append(_inline_plain(text[pos:m.start()]))
        out.append(img(m.group(2), m.group(1)))
        pos = m.end()
    out.append(_inline_plain(text[pos:]))
    return "".join(out)


def _inline_plain(text: str) -> str:
    s = html.escape(text, quote=False)
    s = re.sub(r"`([^`]+)`", r"<code>\1</code>", s)
    s = re.sub(r"\*\*([^*]+)\*\*", r"<strong>\1</strong>", s)
    s = re.sub(r"\[([^\]]+)\]\(([^)\s]+)\)", r'<a href="\2">\1</a>', s)  # a link (images are taken before)
    s = re.sub(r"(?<![\w*])\*([^*\s][^*]*)\*(?![\w*])", r"<em>\1</em>", s)
    return s


def _table_html(lines: list[str], img) -> str:
    def cells(line: str) -> list[str]:
        return [c.strip() for c in line.strip().strip("|").split("|")]

    head = cells(lines[0])
    aligns = ["right" if c.endswith(":") and not c.startswith(":") else "left" for c in cells(lines[1])]
    rows = ["<tr>" + "".join(f"<th style=\"text-align:{a}\">{_inline(c, img)}</th>" for c, a in
                             zip(head, aligns, strict=False)) + "</tr>"]
    for line in lines[2:]:
        rows.append("<tr>" + "".join(f"<td style=\"text-align:{a}\">{_inline(c, img)}</td>" for c, a in
                                     zip(cells(line), aligns, strict=False)) + "</tr>")
    return "<table>\n" + "\n".join(rows) + "\n</table>"


def markdown_to_html(markdown: str, img) -> str:
    """The subset of Markdown the experiments write, as HTML body content."""
    out, lines, i = [], markdown.splitlines(), 0
    while i < len(lines):
        line = lines[i]
        if not line.strip():
            i += 1
            continue
        m = re.match(r"^(#{1,6}) (.*)$", line)
        if m:
            level = len(m.group(1))
            out.append(f"<h{level}>{_inline(m.group(2), img)}</h{level}>")
            i += 1
        elif line.lstrip().startswith("|"):
            block = []
            while i < len(lines) and lines[i].lstrip().startswith("|"):
                block.append(lines[i])
                i += 1
            out.append(_table_html(block, img) if len(block) >= 2 else _inline(block[0], img))
        elif line.startswith("- "):
            items = []
            while i < len(lines) and lines[i].startswith("- "):
                items.append(f"<li>{_inline(lines[i][2:], img)}</li>")
                i += 1
            out.append("<ul>\n" + "\n".join(items) + "\n</ul>")
        else:
            para = []
            while i < len(lines) and lines[i].strip() and not re.match(r"^(#{1,6} |\||- )", lines[i].lstrip()):
                para.append(lines[i])
                i += 1
            out.append(f"<p>{_inline(' '.join(para), img)}</p>")
    return "\n".join(out)


_STYLE = """
body { font-family: system-ui, sans-serif; max-width: 1280px; margin: 2em auto; padding: 0 1em; color: #222; }
table { border-collapse: collapse; margin: 0.8em 0; font-size: 0.88em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.55em; }
th { background: #f2f2f2; }
img { max-width: 100%; border: 1px solid #ddd; margin: 0.5em 0; }
code { background: #f4f4f4; padding: 0 0.2em; }
h2 { border-bottom: 2px solid #888; margin-top: 2em; }
"""


def html_page(markdown: str, title: str, base: str | Path) -> str:
    """A self-contained HTML page of ``markdown``: its PNG images (paths relative to ``base``) inlined."""
    base = Path(base).resolve()

    def img(src: str, alt: str) -> str:
        p = (base / src).resolve()
        if not p.is_file():
            return f"<em>(missing figure {html.escape(src)})</em>"
        data = base64.b64encode(p.read_bytes()).decode("ascii")
        return f'<img alt="{html.escape(alt)}" src="data:image/png;base64,{data}">'

    return (f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{html.escape(title)}</title>"
            f"<style>{_STYLE}</style></head>\n<body>\n{markdown_to_html(markdown, img)}\n</body></html>\n")


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
