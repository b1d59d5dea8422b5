"""README.md's Python API block runs as it stands, and its figures match the simulator's truth."""

from __future__ import annotations

import contextlib
import io
import re

import pytest
from conftest import REPO

MARKER = "<!-- readme-api: tests/test_readme.py runs the next block -->"


def readme_api_block() -> str:
    text = (REPO / "README.md").read_text()
    assert MARKER in text, "README.md lost its Python API block's marker"
    m = re.match(r"\s*```python\n(.*?)```", text.split(MARKER, 1)[1], re.S)
    assert m, "no ```python block right after the marker"
    return m.group(1)


def test_the_block_is_about_ten_lines_of_simulate_run_evaluate():
    code = [line for line in readme_api_block().splitlines() if line.strip() and not line.startswith(("import",
                                                                                                       "from"))]
    assert len(code) <= 10
    block = readme_api_block()
    for name in ("simulate_scene", "open_sequence", "register_frame", "run_method", "evaluate_trajectory"):
        assert name in block


def run_readme_api_block() -> dict[str, float]:
    """Run the block in the current folder; the figures it printed, by label."""
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        exec(compile(readme_api_block(), "README.md", "exec"), {"__name__": "readme"})  # noqa: S102
    return {label: float(v) for label, v in (line.rsplit(":", 1) for line in printed.getvalue().splitlines())}


@pytest.mark.slow
def test_the_readme_python_api_block_runs_and_runs_again(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    figures = run_readme_api_block()
    assert set(figures) == {"salo, frame by frame", "bl, staged"}
    # 10 frames of a VLP-16 in a city with 3 cm noise: registered to centimetres, against the truth
    assert all(0.0 < v < 0.05 for v in figures.values())
    assert (tmp_path / "seqs" / "city" / "manifest.json").is_file()
    # a reader runs it again where the sequence now exists: it is replaced, the same seed giving the same figures
    assert run_readme_api_block() == figures
