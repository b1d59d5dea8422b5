"""Markdown to one self-contained HTML page: the experiments' reports and the leaderboard's page.

``markdown_to_html`` renders the subset of Markdown the experiments and the
leaderboard write (headings, paragraphs, bullet lists, pipe tables, images,
bold, italics, inline code); ``html_page`` wraps it in a page with its PNG
images embedded as base64 data URIs, so the file can be mailed or archived alone.
"""

from __future__ import annotations

import base64
import html
import re
from pathlib import Path

# A Markdown image, ![alt](path): group 1 the alt text, group 2 the path.
MARKDOWN_IMAGE = re.compile(r"!\[([^\]]*)\]\(([^)\s]+)\)")


def _inline(text: str, img) -> str:
    """Inline Markdown (images, links, bold, code) to HTML; ``img(src, alt)`` renders an image."""
    out, pos = [], 0
    for m in MARKDOWN_IMAGE.finditer(text):
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


__all__ = ["MARKDOWN_IMAGE", "html_page", "markdown_to_html"]
