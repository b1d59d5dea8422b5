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


@pytest.mark.slow
def test_the_readme_python_api_block_runs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        exec(compile(readme_api_block(), "README.md", "exec"), {"__name__": "readme"})  # noqa: S102
    figures = dict(line.rsplit(":", 1) for line in printed.getvalue().splitlines())
    assert set(figures) == {"salo, frame by frame", "bl, staged"}
    # 10 frames of a VLP-16 in a city with 3 cm noise: registered to centimetres, against the truth
    assert all(0.0 < float(v) < 0.05 for v in figures.values())
    assert (tmp_path / "seqs" / "city" / "manifest.json").is_file()
