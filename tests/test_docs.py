"""README.md and docs/*.md keep working: their links resolve, their commands parse against the real CLI,
the cheap ones run, and the blocks marked to run (the README's first steps, the format's reference reader)
run and agree with the simulator's truth.

A fenced block may be preceded by a marker line: ``<!-- docs-test: run -->`` (a shell block: every line is
run as written, in a scratch folder: slow), ``<!-- docs-test: reference-reader -->`` (the sequence format's
reader, compared field by field with the simulator's truth), or the README's ``readme-api`` marker
(tests/test_readme.py runs that block). Every other shell line is parsed: a ``salo`` command by the real
parser (``tools.cli.build_parser``), a ``python -m tools.X`` by that module's own parser, its odometry
``--set`` keys against the declarations; ``make`` targets must exist in the Makefile, scripts on disk.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import io
import os
import re
import shlex
import stat
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from conftest import REPO

PAGES = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
MARKER = re.compile(r"<!--\s*(?:docs-test:\s*([\w-]+)|(readme-api)[^>]*)\s*-->")
README_MAX_LINES = 250
# salo commands cheap enough to run in the fast suite (they print tables and exit)
CHEAP_SALO = {("scenes",), ("sensors",)}
# commands whose --set is an odometry parameter (salo simulate / view / scene take scene parameters)
ODOMETRY_SET = {"odometry", "experiment", "bench", "regress", "tools.bench_real", "tools.open_loop",
                "tools.bench_odometry"}


@dataclass(frozen=True)
class Block:
    page: Path
    line: int  # of the opening fence, 1-based
    lang: str
    text: str
    marker: str | None

    def __str__(self) -> str:
        return f"{self.page.relative_to(REPO)}:{self.line}"


def blocks(page: Path) -> list[Block]:
    """The fenced code blocks of a Markdown page, each with the marker on the line before its fence."""
    out, lines = [], page.read_text().splitlines()
    k = 0
    while k < len(lines):
        m = re.match(r"^(\s*)```(\S*)\s*$", lines[k])
        if not m:
            k += 1
            continue
        indent, lang, start = m.group(1), m.group(2), k
        body = []
        k += 1
        while k < len(lines) and lines[k].strip() != "```":
            body.append(lines[k][len(indent):] if lines[k].startswith(indent) else lines[k])
            k += 1
        before = next((lines[j] for j in range(start - 1, -1, -1) if lines[j].strip()), "")
        mk = MARKER.search(before)
        marker = (mk.group(1) or mk.group(2)) if mk else None
        out.append(Block(page, start + 1, lang, "\n".join(body) + "\n", marker))
        k += 1
    return out


ALL_BLOCKS = [b for page in PAGES for b in blocks(page)]


def block_ids(items) -> list[str]:
    return [str(b) for b in items]


def shell_lines(block: Block) -> list[list[str]]:
    """The commands of a shell block: each line (continuations joined) split as the shell does, comments out."""
    text = block.text.replace("\\\n", " ")
    return [tokens for line in text.splitlines() if (tokens := shlex.split(line, comments=True))]


def without_env(tokens: list[str]) -> tuple[dict, list[str]]:
    """Leading ``NAME=value`` assignments apart from the command."""
    env = {}
    while tokens and re.match(r"^[A-Z_][A-Z0-9_]*=", tokens[0]):
        name, _, value = tokens[0].partition("=")
        env[name] = value
        tokens = tokens[1:]
    return env, tokens


# ---------------------------------------------------------------- headings and links
def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def anchors(page: Path) -> set[str]:
    seen: dict[str, int] = {}
    out = set()
    fenced = False
    for line in page.read_text().splitlines():
        if line.lstrip().startswith("```"):
            fenced = not fenced
            continue
        m = None if fenced else re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if m:
            base = slug(m.group(1))
            n = seen.get(base, 0)
            seen[base] = n + 1
            out.add(base if n == 0 else f"{base}-{n}")
    return out


def links(page: Path) -> list[tuple[int, str]]:
    """(line, target) of every Markdown link and image outside code."""
    out, fenced = [], False
    for k, line in enumerate(page.read_text().splitlines(), 1):
        if line.lstrip().startswith("```"):
            fenced = not fenced
            continue
        if fenced:
            continue
        line = re.sub(r"`[^`]*`", "", line)
        out += [(k, m.group(1)) for m in re.finditer(r"\]\(([^)\s]+)\)", line)]
    return out


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(REPO)))
def test_every_link_resolves_to_a_file_and_its_heading(page):
    bad = []
    for line, target in links(page):
        if re.match(r"^[a-z]+:", target):  # http:, mailto:
            continue
        path, _, anchor = target.partition("#")
        dest = (page.parent / path).resolve() if path else page
        if not dest.exists():
            bad.append(f"line {line}: {target}: no such file")
        elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            bad.append(f"line {line}: {target}: no heading '#{anchor}' in {dest.name}")
    assert not bad, "\n".join(bad)


def test_every_docs_page_is_linked_from_the_readme():
    linked = {(REPO / t.partition("#")[0]).resolve() for _, t in links(REPO / "README.md")}
    missing = [p.name for p in PAGES[1:] if p.resolve() not in linked]
    assert not missing, f"docs pages the README does not link: {missing}"


def test_the_readme_is_a_front_door():
    assert len((REPO / "README.md").read_text().splitlines()) <= README_MAX_LINES


def test_the_readme_and_ci_give_the_same_test_command():
    quickstart = next(b for b in blocks(REPO / "README.md") if b.lang == "sh")
    commands = [" ".join(t) for t in shell_lines(quickstart)]
    assert commands[:2] == ["make demo", "make test"]
    ci = (REPO / ".ci" / "run").read_text().splitlines()
    assert "make test" in [line.strip() for line in ci]


# ---------------------------------------------------------------- commands against the real parsers
class _Parsed(Exception):
    def __init__(self, parser):
        self.parser = parser


def module_parser(module: str) -> argparse.ArgumentParser:
    """The argument parser ``python -m MODULE`` builds: its ``main`` is called until it parses."""
    mod = importlib.import_module(module)
    real = argparse.ArgumentParser.parse_args

    def capture(self, *args, **kwargs):
        raise _Parsed(self)

    argparse.ArgumentParser.parse_args = capture
    try:
        mod.main()
    except _Parsed as got:
        return got.parser
    finally:
        argparse.ArgumentParser.parse_args = real
    raise AssertionError(f"{module}.main() never parsed its arguments")


def parse(parser: argparse.ArgumentParser, args: list[str]) -> argparse.Namespace:
    """``parser.parse_args(args)``, its error message raised as an AssertionError instead of an exit."""
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        try:
            return parser.parse_args(args)
        except SystemExit:
            raise AssertionError(err.getvalue().strip().splitlines()[-1]) from None


def check_odometry_sets(name: str, args: argparse.Namespace) -> None:
    from odometry.config import changes_from_assignments

    sets = getattr(args, "set", None) or []
    if name in ODOMETRY_SET and sets:
        changes_from_assignments(sets)  # ConfigError on a key or value the odometry does not have


def check_command(tokens: list[str], make_targets: set[str]) -> str:
    """Check one shell command against what it calls; returns what kind it was."""
    _, tokens = without_env(tokens)
    prog, args = tokens[0], tokens[1:]
    if prog == "salo":
        from tools.cli import build_parser

        ns = parse(build_parser(), args)
        check_odometry_sets(next(a for a in args if not a.startswith("-")), ns)  # the command's name
        return "salo"
    if prog == "python" and args[:1] == ["-m"]:
        module = args[1]
        assert module.startswith("tools."), f"python -m {module}: not one of the project's tools"
        ns = parse(module_parser(module), args[2:])
        check_odometry_sets(module, ns)
        return "python -m"
    if prog == "python":
        assert (REPO / args[0]).is_file(), f"{args[0]}: no such script"
        return "script"
    if prog == "make":
        missing = set(args) - make_targets
        assert not missing, f"make {' '.join(args)}: no target {sorted(missing)} in the Makefile"
        return "make"
    if prog == "bash":
        script = REPO / args[0]
        assert script.is_file(), f"{args[0]}: no such script"
        if script.name == "regress.sh":
            assert args[1:] in ([], ["--update"]), f"{args[0]} takes no argument but --update"
        return "bash"
    if prog == "pip":
        return "pip"
    raise AssertionError(f"'{prog}': a command this test does not know how to check")


SHELL_BLOCKS = [b for b in ALL_BLOCKS if b.lang in ("sh", "bash")]


@pytest.fixture(scope="module")
def make_targets() -> set[str]:
    text = (REPO / "Makefile").read_text()
    return {m.group(1) for m in re.finditer(r"^([\w-]+):", text, re.M)}


@pytest.mark.parametrize("block", SHELL_BLOCKS, ids=block_ids(SHELL_BLOCKS))
def test_every_shell_command_parses_against_the_real_command_line(block, make_targets):
    assert shell_lines(block), f"{block}: an empty shell block"
    for tokens in shell_lines(block):
        try:
            check_command(tokens, make_targets)
        except Exception as exc:  # name the line
            raise AssertionError(f"{block}: {shlex.join(tokens)}\n  {type(exc).__name__}: {exc}") from None


def cheap_salo_commands() -> list[tuple[Block, list[str]]]:
    out = []
    for b in SHELL_BLOCKS:
        for tokens in shell_lines(b):
            if tokens[0] == "salo" and (tuple(tokens[1:2]) in CHEAP_SALO or "--keys" in tokens):
                out.append((b, tokens))
    return out


@pytest.mark.parametrize("block, tokens", cheap_salo_commands(),
                         ids=[f"{b} {' '.join(t)}" for b, t in cheap_salo_commands()])
def test_the_cheap_commands_run(block, tokens):
    from tools.cli import main

    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert main(tokens[1:]) == 0
    assert printed.getvalue().strip()


def test_the_toml_blocks_are_toml():
    tomllib = pytest.importorskip("tomllib")  # Python >= 3.11
    for b in (b for b in ALL_BLOCKS if b.lang == "toml"):
        tomllib.loads(b.text)


def test_every_python_block_is_run_by_a_test():
    known = {"readme-api", "reference-reader"}
    loose = [str(b) for b in ALL_BLOCKS if b.lang == "python" and b.marker not in known]
    assert not loose, f"Python blocks no test runs (give them a docs-test marker and a test): {loose}"


# ---------------------------------------------------------------- the sequence format's reference reader
def reference_reader() -> dict:
    (block,) = [b for b in ALL_BLOCKS if b.marker == "reference-reader"]
    namespace: dict = {"__name__": "reference_reader"}
    exec(compile(block.text, str(block), "exec"), namespace)  # noqa: S102
    return namespace


@pytest.mark.parametrize("preset, compress", [("vlp16", False), ("salo32", True)])
def test_the_format_page_s_reference_reader_reads_the_truth(tmp_path, preset, compress):
    """The spec, followed literally, gives back the simulator's own float64 truth within the bounds it states."""
    from simlidar.sensor import load_sensor
    from simlidar.simulate import simulate_sequence
    from tests.helpers import constant_velocity
    from tests.test_truth_format import _street_world

    sensor = load_sensor(preset).with_overrides(angular_jitter_deg=0.02)  # vlp16: lasers fire one by one
    world = _street_world()
    traj = constant_velocity(v=(12.0, 1.5, 0.2), yaw_rate=0.8, start=(-20.0, 0.0, 1.9), duration=5.0)
    scans = []
    out = tmp_path / "seq"
    simulate_sequence(world, traj, sensor, out, frames=2, seed=3, compress_truth=compress,
                      on_frame=lambda k, scan: scans.append(scan))
    assert (out / "sidecar" / "000001.truth").read_bytes()[17] == (1 if compress else 0)
    read_frame = reference_reader()["read_frame"]
    for k, scan in enumerate(scans):
        got = read_frame(out, k)
        assert len(got["xyz"]) == len(scan.xyz) > 1000
        for name in ("ring", "azimuth_index", "object_id"):
            assert np.array_equal(got[name], getattr(scan, name)), name
        assert np.array_equal(got["time_s"], scan.time_s)
        assert np.all(np.abs(got["range_m"] - scan.range_m) <= 2e-7 * scan.range_m)
        err = np.linalg.norm(got["true_xyz"] - scan.true_xyz, axis=1)
        assert np.all(err <= 4e-7 * scan.true_range_m + 1e-6), (err / (4e-7 * scan.true_range_m + 1e-6)).max()
        assert np.linalg.norm(scan.true_xyz - scan.xyz, axis=1).max() > 0.5  # the knots did matter
        cos = np.clip(np.einsum("ij,ij->i", got["normal"], scan.normal), -1.0, 1.0)
        assert np.degrees(np.arccos(cos)).max() < 0.01
        assert set(got["label"]) <= {"ground", "building"}


# ---------------------------------------------------------------- blocks that run as written
RUN_BLOCKS = [b for b in ALL_BLOCKS if b.marker == "run"]


def _wrapper(folder: Path, name: str, command: str) -> None:
    path = folder / name
    path.write_text(f'#!/bin/sh\nexec {command} "$@"\n')
    path.chmod(path.stat().st_mode | stat.S_IXUSR)


@pytest.mark.slow
@pytest.mark.parametrize("block", RUN_BLOCKS, ids=block_ids(RUN_BLOCKS))
def test_the_blocks_marked_to_run_run_as_written(block, tmp_path):
    """As a reader runs them from the repository's root with the environment active: `salo` and `python`
    on the path (this interpreter), the repository's files where the commands name them."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    _wrapper(bin_dir, "salo", f"{shlex.quote(sys.executable)} -m tools.cli")
    _wrapper(bin_dir, "python", shlex.quote(sys.executable))
    work = tmp_path / "work"
    work.mkdir()
    (work / "examples").symlink_to(REPO / "examples")
    env = {**os.environ, "PATH": f"{bin_dir}{os.pathsep}{os.environ['PATH']}",
           "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))}
    for line in block.text.splitlines():
        if not shlex.split(line, comments=True):
            continue
        done = subprocess.run(["bash", "-c", line], cwd=work, env=env, capture_output=True, text=True, timeout=900)
        assert done.returncode == 0, f"{block}: {line}\n{done.stderr[-2000:]}"
    if block.page.name == "README.md":  # what the first steps say they write
        for path in ("seqs/city1/manifest.json", "city1.png", "out/city1/salo-map/poses.txt", "city1-eval.png",
                     "out/bench/suite/leaderboard.html"):
            assert (work / path).is_file(), path
