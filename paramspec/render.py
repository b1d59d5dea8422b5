"""Help text and Markdown tables from the declarations: what ``--help``, ``salo scenes NAME`` and the docs show."""

from __future__ import annotations

from typing import Any

from .declare import Param, Section, number_text


def value_text(value: Any) -> str:
    """A default as YAML would write it: null, true, 500.0, [a, b], "" for the empty string."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, list | tuple):
        return "[" + ", ".join(value_text(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {value_text(v)}" for k, v in value.items()) + "}"
    if value == "":
        return '""'
    return str(value)


def default_text(p: Param) -> str:
    return "required" if p.required else value_text(p.default)


def range_text(p: Param, sep: str = "|") -> str:
    """The allowed values: 'arch|box', '[2, 12]', '>= 0', or '' (no bounds)."""
    if p.choices is not None:
        return sep.join(str(c) for c in p.choices)
    return p.bounds()


def _rows(sec: Section) -> list[tuple[str, Param | Section]]:
    return list(sec.walk())


def help_text(sec: Section, indent: str = "  ", header: bool = False) -> str:
    """One line per key: name, type, default, unit, range, help; a nested section's line heads its keys.

    Columns are as wide as their widest entry (keys, defaults and ranges up to 40, 12 and
    18 characters: longer ones push their line out); ``header``: a first line naming the columns.
    """
    rows = _rows(sec)
    params = [(n, p) for n, p in rows if isinstance(p, Param)]
    if not params:
        return ""
    width = min(40, max(len(n) for n, _ in params))
    tw = max(len(p.type) for _, p in params)
    dw = min(12, max(len(default_text(p)) for _, p in params))
    uw = max(len(p.unit) for _, p in params)
    rw = min(18, max(len(range_text(p)) for _, p in params))
    tw, uw, rw = max(tw, 4), max(uw, 4), max(rw, 5)
    lines = []
    if header:
        lines.append(indent + " ".join([f"{'key':<{width}}", f"{'type':<{tw}}", f"{'default':<{dw}}",
                                        f"{'unit':<{uw}}", f"{'range':<{rw}}", "meaning"]))
    for name, m in rows:
        if isinstance(m, Section):
            lines.append(f"{indent}{name}: {m.help}".rstrip())
            continue
        cells = [f"{name:<{width}}", f"{m.type:<{tw}}", f"{default_text(m):<{dw}}", f"{m.unit:<{uw}}",
                 f"{range_text(m):<{rw}}", m.help]
        lines.append((indent + " ".join(cells)).rstrip())
    return "\n".join(lines)


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def markdown(sec: Section) -> str:
    """A Markdown table of the keys (dotted names for nested sections' keys, a row heading each section)."""
    out = ["| key | type | default | unit | range | meaning |", "|---|---|---|---|---|---|"]
    for name, m in _rows(sec):
        if isinstance(m, Section):
            out.append(f"| **{name}** | section | | | | {_cell(m.help)} |")
            continue
        rng = range_text(m, sep=", ")
        if m.nullable:
            rng = f"{rng}, or null" if rng else "or null"
        cells = [f"`{name}`", m.type, f"`{default_text(m)}`" if not m.required else "required",
                 m.unit, rng, m.help]
        out.append("| " + " | ".join(_cell(c) for c in cells) + " |")
    return "\n".join(out)


__all__ = ["default_text", "help_text", "markdown", "number_text", "range_text", "value_text"]
