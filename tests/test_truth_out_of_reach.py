"""The truth is out of a method's reach, by construction: a cheat searches for it and finds nothing.

``tests/truth_cheat.py`` searches by link target, by inode and by walking up from every
path and environment variable it is handed, as a command (``salo bench --command``,
``salo regress --odometry-command``) and as a plug-in of the entry-point group
``salo.methods`` (both commands). The caller's working folder holds the bench's output,
sequences and truth included, the worst case. What it finds must hold none of the
sequences' truth; a control shows the same search does find it from a hard link or a
symbolic link into a sequence folder (the staging of old) and from a folder beside one.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import yaml

from tools import cli

HERE = Path(__file__).parent
SUITE = {"name": "tiny", "scenes": ["city"], "sensors": ["vlp16"], "frames": 4, "speed_m_s": 8.0, "start_s": 4.0}


@pytest.fixture
def cheats(tmp_path_factory, monkeypatch):
    """The cheat as a command line and as an installed plug-in ("cheat-plugin"); its reports' file."""
    pkg = tmp_path_factory.mktemp("cheat-site")
    shutil.copy(HERE / "truth_cheat.py", pkg / "truth_cheat.py")
    (pkg / "cheat_plugin.py").write_text(textwrap.dedent("""
        import os, sys
        import numpy as np
        import truth_cheat

        def run(sequence):
            given = [str(sequence.path), *map(str, getattr(sequence, "scan_files", None) or []), *sys.argv,
                     *sys.path]
            truth_cheat.report(truth_cheat.search(given, dict(os.environ), os.getcwd()), kind="plugin")
            return np.tile(np.eye(4), (len(sequence), 1, 1))
    """))
    info = pkg / "cheat_plugin-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: cheat-plugin\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text("[salo.methods]\ncheat-plugin = cheat_plugin:run\n")
    monkeypatch.syspath_prepend(str(pkg))
    reports = tmp_path_factory.mktemp("cheat-reports") / "reports.jsonl"
    monkeypatch.setenv("SALO_CHEAT_REPORT", str(reports))
    command = (f"{sys.executable} {pkg / 'truth_cheat.py'} {{sensor}} {{times}} {{fields}} {{sequence}} "
               "{scans} {out}")
    return command, reports


def _truths(root: Path) -> dict[Path, np.ndarray]:
    """Every simulated sequence folder under ``root`` and its true poses (N, 12)."""
    return {m.parent: np.loadtxt(m.parent / "poses.txt", ndmin=2) for m in root.rglob("manifest.json")
            if (m.parent / "poses.txt").is_file()}


def _holds_truth(path: str, truths: dict[Path, np.ndarray]) -> bool:
    """A file the cheat found is the truth when it sits in a sequence folder or holds a sequence's poses."""
    p = Path(path).resolve()
    if any(folder.resolve() in p.parents for folder in truths):
        return True
    if p.name != "poses.txt":
        return False
    try:
        rows = np.loadtxt(p, ndmin=2)
    except (OSError, ValueError):
        return False
    return any(rows.shape == t.shape and np.allclose(rows, t, atol=1e-6) for t in truths.values())


def _reports(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines()]


def _handed_links(report: dict) -> list:
    """The symbolic and hard links the cheat met in what the bench staged for it (the staging of old: a
    link into the sequence folder). Links elsewhere on its search (a virtual environment's ``lib64`` and
    ``python3``, reached through ``sys.path``) are the machine's, not the bench's."""
    return [link for link in report["links"] + report["hard_links"] if "salo-input-" in link[0]]


def _check(reports: list[dict], truths: dict, kinds: set[str]) -> None:
    assert {r["kind"] for r in reports} == kinds
    for r in reports:
        assert r["examined"] > 100 and not _handed_links(r)  # it searched; the stage holds no link to follow
        into_truth = [t for _, t in r["links"] if _holds_truth(t, truths)
                      or Path(t).resolve() in {f.resolve() for f in truths}]
        assert into_truth == [], f"the {r['kind']} cheat met links into a sequence folder: {into_truth}"
        assert any("salo-input-" in p for p in r["searched_from"])  # it was handed the staged folder
        reached = [f for f in r["found"] if _holds_truth(f, truths)]
        assert reached == [], f"the {r['kind']} cheat reached the truth: {reached}"


@pytest.mark.slow
def test_bench_hands_a_cheat_nothing_that_leads_to_the_truth(tmp_path, cheats, monkeypatch):
    command, reports = cheats
    suite = tmp_path / "tiny.yaml"
    suite.write_text(yaml.safe_dump(SUITE))
    monkeypatch.chdir(tmp_path)  # the caller's folder holds the bench's output, truth included
    code = cli.main(["bench", "--suite", str(suite), "--out", "bench", "--method", "cheat-plugin",
                     "--command", f"cheat={command}"])
    assert code == 0
    truths = _truths(tmp_path / "bench")
    assert len(truths) == 1  # the bench keeps its sequences (its cache), truth and all, in its output
    _check(_reports(reports), truths, {"command", "plugin"})
    rows = [json.loads(p.read_text()) for p in (tmp_path / "bench" / "results").rglob("result.json")]
    assert sorted(r["method"] for r in rows) == ["cheat", "cheat-plugin"]
    for r in rows:  # what a cheat that finds nothing gives: the identity, metres off the truth's path
        assert r["status"] == "ok" and r["figures"]["ate_aligned_m"] > 0.2


@pytest.mark.slow
def test_regress_hands_a_cheat_nothing_and_leaves_no_truth_behind(tmp_path, cheats, monkeypatch, capsys):
    command, reports = cheats
    suite = tmp_path / "tiny.yaml"
    suite.write_text(yaml.safe_dump(SUITE))  # a spec whose keep_sequences is true by default
    monkeypatch.chdir(tmp_path)
    common = ["regress", "--suite", str(suite), "--baseline-dir", "baselines", "--update", "--workers", "1"]
    assert cli.main([*common, "--out", "reg", "--method", "cheat", "--odometry-command", command]) == 0
    assert cli.main([*common, "--out", "reg", "--method", "cheat-plugin"]) == 0
    capsys.readouterr()
    # Simulated in memory: nothing of the truth was written, in the output folder or anywhere here.
    assert _truths(tmp_path) == {}
    assert not list(tmp_path.rglob("manifest.json")) and not list(tmp_path.rglob("degeneracy.csv"))
    assert {p.relative_to(tmp_path).parts[:2] for p in tmp_path.rglob("poses.txt")} == {("reg", "runs")}  # theirs
    assert not (tmp_path / "reg" / "sequences").exists() or not any((tmp_path / "reg" / "sequences").iterdir())
    # The cheats searched what they were handed and found nothing: their baselines are the identity's figures.
    found = _reports(reports)
    assert {r["kind"] for r in found} == {"command", "plugin"}
    for r in found:
        assert r["examined"] > 100 and not _handed_links(r)
        assert not [f for f in r["found"] if Path(f).name == "poses.txt" and tmp_path in Path(f).parents]
    for method in ("cheat", "cheat-plugin"):
        (figures,) = json.loads((tmp_path / "baselines" / "tiny" / f"{method}.json").read_text())["runs"].values()
        assert figures["ate_aligned_rmse_m"] > 0.2
    # Asked to keep its sequences on disk, regress keeps them in its output, and still hands over copies.
    reports.unlink()
    assert cli.main([*common, "--out", "kept", "--method", "cheat", "--odometry-command", command,
                     "--keep-sequences"]) == 0
    truths = _truths(tmp_path / "kept")
    assert len(truths) == 1
    _check(_reports(reports), truths, {"command"})


def test_the_cheat_finds_the_truth_from_a_link_into_a_sequence_folder(tmp_path):
    """The control: the same search, handed what the staging of old handed over, reaches the truth."""
    sys.path.insert(0, str(HERE))
    try:
        import truth_cheat
    finally:
        sys.path.remove(str(HERE))
    seq = tmp_path / "out" / "sequences" / "abc"
    (seq / "velodyne").mkdir(parents=True)
    (seq / "velodyne" / "000000.bin").write_bytes(np.zeros(4, np.float32).tobytes())
    truth = np.tile(np.eye(4)[:3].ravel(), (3, 1))
    truth[:, 3] = np.random.default_rng(39).uniform(1, 50, 3)  # a truth of its own, no other file's
    np.savetxt(seq / "poses.txt", truth)
    (seq / "manifest.json").write_text("{}")
    truths = _truths(tmp_path)
    hard = tmp_path / "stage-hard" / "input" / "velodyne"  # hard links (the staging before this test)
    hard.mkdir(parents=True)
    os.link(seq / "velodyne" / "000000.bin", hard / "000000.bin")
    soft = tmp_path / "stage-soft" / "input"
    soft.mkdir(parents=True)
    (soft / "velodyne").symlink_to(seq / "velodyne")
    beside = seq.parent / "stage" / "input"  # a staging folder inside the output tree
    beside.mkdir(parents=True)
    for given in (hard, soft / "velodyne", beside):
        result = truth_cheat.search([str(given)], {}, str(given))
        assert any(_holds_truth(f, truths) for f in result["found"]), given
    clean = tmp_path.parent / (tmp_path.name + "-elsewhere") / "input"  # outside the output tree, copies
    (clean / "velodyne").mkdir(parents=True)
    shutil.copyfile(seq / "velodyne" / "000000.bin", clean / "velodyne" / "000000.bin")
    result = truth_cheat.search([str(clean / "velodyne")], {}, str(clean))
    assert not [f for f in result["found"] if _holds_truth(f, truths)]


def test_a_command_runs_in_a_folder_of_its_own_and_a_relative_path_gets_a_hint(tmp_path, monkeypatch):
    from simlidar.sensor import load_sensor
    from tools.methods import CommandMethod, MethodError, run_method
    from tools.runners import simulate_scene
    from tools.worlds import build_scene_world

    seq = simulate_scene(build_scene_world("city", 0, {"speed_m_s": 8.0}), load_sensor("vlp16"), tmp_path / "seq",
                         2, seed=0, start_s=4.0).path
    (tmp_path / "bin").mkdir()
    script = tmp_path / "bin" / "where.py"  # writes the identity poses and the folder it runs in
    script.write_text("import os, sys\nopen(sys.argv[1], 'w').write('1 0 0 0 0 1 0 0 0 0 1 0\\n' * 2)\n"
                      "print('cwd', os.getcwd(), 'PWD', os.environ.get('PWD'), 'OLDPWD', os.environ.get('OLDPWD'))\n")
    monkeypatch.chdir(tmp_path)  # the caller's folder holds the sequence, truth included
    monkeypatch.setenv("OLDPWD", str(tmp_path / "seq"))
    from simlidar.dataset import open_sequence

    run_method(CommandMethod("where", f"{sys.executable} {script} {{out}} # {{scans}}"), open_sequence(seq),
                      log_path=tmp_path / "where.log")
    words = (tmp_path / "where.log").read_text().split()
    cwd, pwd, oldpwd = words[words.index("cwd") + 1], words[words.index("PWD") + 1], words[-1]
    assert cwd == pwd and Path(cwd).name == "work" and "salo-input-" in cwd and oldpwd == "None"
    with pytest.raises(MethodError, match=r"runs in a folder of its own.*give bin/where.py by an absolute path"):
        run_method(CommandMethod("rel", f"{sys.executable} bin/where.py {{out}} # {{scans}}"),
                          open_sequence(seq), log_path=tmp_path / "rel.log")
