"""salo bench (tools.leaderboard): methods over a suite, results per method and sequence, the leaderboard page.

A one-sequence suite keeps it fast; the ranking is checked against the
simulator's truth (a constant-velocity guess must rank below our odometry).
"""

from __future__ import annotations

import json
import sys
import textwrap

import pytest
import yaml

from tools import cli
from tools.leaderboard import run_bench
from tools.methods import CommandMethod, method_from_name

SUITE = {"name": "tiny", "scenes": ["city"], "sensors": ["vlp16"], "frames": 6, "speed_m_s": 8.0, "start_s": 4.0}


@pytest.fixture
def guess(tmp_path):
    script = tmp_path / "guess.py"  # 0.5 m per frame straight ahead: the truth drives 0.8 m per frame and turns
    script.write_text(textwrap.dedent("""
        import sys
        from pathlib import Path
        import numpy as np
        n = len(list(Path(sys.argv[1]).glob("*.bin")))
        poses = np.tile(np.eye(4)[:3].ravel(), (n, 1))
        poses[:, 3] = 0.5 * np.arange(n)
        np.savetxt(sys.argv[2], poses, fmt="%.9f")
    """))
    return f"{sys.executable} {script} {{scans}} {{out}}"


@pytest.mark.slow
def test_bench_ranks_methods_against_the_truth_and_adds_one_without_rerunning(tmp_path, guess, capsys):
    suite = tmp_path / "tiny.yaml"
    suite.write_text(yaml.safe_dump(SUITE))
    out = tmp_path / "bench"
    first = run_bench(suite, [method_from_name("bl"), CommandMethod("guess", guess)], out)
    assert first.ran == 2 and first.reused == 0 and not first.failures
    (seq,) = first.sequences
    by = {r["method"]: r for r in first.results}
    assert by["bl"]["figures"]["ate_aligned_m"] < by["guess"]["figures"]["ate_aligned_m"]
    assert by["bl"]["fields"] == ["ring", "time_s"] and by["bl"]["has_diagnostics"]
    md = (out / "leaderboard.md").read_text()
    table = [line for line in md.splitlines() if line.startswith("| 1 |") or line.startswith("| 2 |")]
    assert table[0].startswith("| 1 | BL |") and table[1].startswith("| 2 | guess |")
    for name in ("trajectories", "error_over_distance", "error_vs_eigenvalue"):
        assert (out / "figures" / seq.id / f"{name}.png").stat().st_size > 5_000
    html = (out / "leaderboard.html").read_text()
    assert html.count("data:image/png;base64,") == 3 and "<table>" in html
    # A method added later runs alone; the page shows all three; a command that cheats fails in its row.
    code = cli.main(["bench", "--suite", str(suite), "--out", str(out), "--command",
                     "cheat=cp {sequence}/poses.txt {out}"])
    text = capsys.readouterr().out
    assert code == 0 and "1 runs, 0 reused" in text and "failed: cheat" in text
    history = json.loads((out / "bench.json").read_text())
    assert len(history) == 2 and history[1]["command"].startswith("salo bench --suite")
    md = (out / "leaderboard.md").read_text()
    assert "| BL |" in md and "| guess |" in md and "| cheat |" in md and "0/1" in md and "1/1" in md
    # Changed settings of ours are another method; the same settings are reused.
    again = run_bench(suite, [method_from_name("bl"), method_from_name("bl", {"filter": {"voxel_size_m": 0.6}})],
                      out)
    assert again.ran == 1 and again.reused == 1


@pytest.mark.slow
def test_bench_over_the_generalize_suite_hands_the_real_kind_no_fields(tmp_path):
    result = run_bench("generalize", [method_from_name("bl")], tmp_path / "g", frames=3, families=("city",))
    families = sorted({s.family for s in result.sequences})
    assert families == ["city (real)", "city (simulated)"]
    for r in result.results:
        assert r["fields"] == ([] if r["family"].endswith("(real)") else ["ring", "time_s"])
    assert "## city (real)" in (tmp_path / "g" / "leaderboard.md").read_text()
