"""Sweeps (tools.sweep) and the regression command: spec validation, keys, store, resume, executors, regress.

Tiny sweeps (VLP-16, a few frames) keep this file fast; the figures are
checked against the ground truth the simulator wrote, not against themselves.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import yaml

from odometry.metrics import evaluate_trajectory
from simlidar.formats.kitti import read_kitti_poses
from tools import cli
from tools.sweep import (
    DaskExecutor,
    InlineExecutor,
    LocalExecutor,
    SpecError,
    Store,
    load_spec,
    plan_sweep,
    read_table,
    run_sweep,
    spec_from_dict,
)
from tools.sweep.store import VOLATILE_COLUMNS

TINY = {"name": "tiny", "scenes": ["city"], "sensors": ["vlp16"], "noise_std_m": [0.01, 0.04],
        "variants": ["bl", "salo"], "frames": 4, "sequences": "disk"}


def _stable(rows: list[dict]) -> list[dict]:
    """Rows without the columns that legitimately differ between executions (timings, host, time)."""
    return [{k: v for k, v in r.items() if k not in VOLATILE_COLUMNS} for r in rows]


@pytest.fixture(scope="module")
def tiny_sweep(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep") / "tiny"
    result = run_sweep(spec_from_dict(TINY), out, LocalExecutor(2))
    return out, result


# ---------------------------------------------------------------- spec
@pytest.mark.parametrize(
    ("change", "key", "words"),
    [
        ({"scene": ["city"]}, "scene", "unknown"),
        ({"scenes": ["mars"]}, "scenes", "unknown scene 'mars'"),
        ({"scenes": []}, "scenes", "empty"),
        ({"seeds": [0, -1]}, "seeds", ">= 0"),
        ({"seeds": [1, 1]}, "seeds", "twice"),
        ({"sensors": ["vlp17"]}, "sensors", "unknown sensor preset"),
        ({"noise_std_m": [0.01, "a"]}, "noise_std_m", ">= 0"),
        ({"variants": ["bl", "icp"]}, "variants", "unknown variant 'icp'"),
        ({"frames": 1}, "frames", ">= 2"),
        ({"speed_m_s": 0}, "speed_m_s", "> 0"),
        ({"scene_params": {"city": {"streets_x": "many"}}}, "scene_params.city.streets_x", "got 'many'"),
        ({"scene_params": {"tunnel": {"length_m": 300}}}, "scene_params.tunnel", "not a scene of this sweep"),
        ({"scene_params": {"city": {"seed": 3}}}, "scene_params.city.seed", "axis"),
        ({"odometry": {"voxel_size": 0.3}}, "odometry.voxel_size", "unknown"),
        ({"odometry": {"filter": {"voxel_size_m": -1}}}, "odometry.filter.voxel_size_m", "> 0"),
        ({"odometry": {"voxel_size_m": 0.5}}, "odometry.voxel_size_m", "did you mean 'odometry.filter.voxel_size_m'?"),
        ({"odometry": {"clean": {"min_range_m": 200}}}, "odometry.clean.min_range_m", "< clean.max_range_m"),
        ({"configs": {"v4": {"match": {"trim_fraction": 1}}}}, "configs.v4.match.trim_fraction", "[0, 1)"),
        ({"commands": {"mine": "my_odometry {sequence}"}}, "commands.mine", "{out}"),
        ({"configs": {"bl": {"filter": {"voxel_size_m": 0.4}}}}, "configs", "already a variant"),
        ({"configs": {"v4": {"base": "loam"}}}, "configs.v4.base", "loam"),
        ({"keep_sequences": "yes"}, "keep_sequences", "true or false"),
    ],
)
def test_spec_errors_name_the_key(change, key, words):
    with pytest.raises(SpecError) as err:
        spec_from_dict({**TINY, **change}, origin="s.yaml")
    assert f"s.yaml: key '{key}'" in str(err.value)
    assert words in str(err.value)


def test_spec_defaults_and_file(tmp_path):
    spec = spec_from_dict({})
    assert (spec.scenes, spec.seeds, spec.sensors, spec.variants) == (("city",), (0,), ("salo32",),
                                                                      ("bl", "ncf", "salo"))
    runs = spec.runs()
    assert [r.variant for r in runs] == ["bl", "ncf", "salo"]
    assert {r.sim.noise_std_m for r in runs} == {0.02}  # the salo32 preset's own noise
    # A sensor file is found relative to the spec, and its noise is swept.
    sensor = tmp_path / "sensors" / "mine.yaml"
    sensor.parent.mkdir()
    sensor.write_text(Path(__file__).resolve().parents[1].joinpath("simlidar/presets/vlp16.yaml").read_text())
    (tmp_path / "s.yaml").write_text(yaml.safe_dump({**TINY, "sensors": ["sensors/mine.yaml"]}))
    spec = load_spec(tmp_path / "s.yaml")
    assert spec.sensors == (str(sensor.resolve()),)
    assert [r.sim.sensor_model.range_noise_std_m for r in spec.runs()] == [0.01, 0.01, 0.04, 0.04]
    # The documented example: 2 scenes x 2 seeds x 3 noise levels x 3 variants over 12 sequences.
    example = load_spec(Path(__file__).resolve().parents[1] / "tools/sweep/examples/noise-study.yaml").runs()
    assert (len(example), len({r.sim_key for r in example})) == (36, 12)


def test_run_keys_are_stable_hashes_of_resolved_parameters():
    runs = spec_from_dict(TINY).runs()
    again = spec_from_dict(dict(reversed(list(TINY.items())))).runs()
    assert [r.key for r in runs] == [r.key for r in again]
    assert len({r.key for r in runs}) == 4
    # Variants share their simulated sequence; noise levels do not.
    assert runs[0].sim_key == runs[1].sim_key != runs[2].sim_key
    # The same run spelled differently: a scalar axis, defaults given explicitly, a number as a string.
    same = spec_from_dict({**TINY, "noise_std_m": 0.01, "variants": "bl", "speed_m_s": 10,
                           "scene_params": {"city": {"streets_x": "4"}}}).runs()
    assert same[0].key == runs[0].key
    # An odometry override changes the run but not the sequence.
    tuned = spec_from_dict({**TINY, "odometry": {"filter": {"voxel_size_m": 0.6}}}).runs()
    assert tuned[0].sim_key == runs[0].sim_key and tuned[0].key != runs[0].key
    # The sensor's resolved model is hashed: its own noise given explicitly is the same sequence.
    own = spec_from_dict({k: v for k, v in TINY.items() if k != "noise_std_m"}).runs()[0]
    assert own.sim_key == spec_from_dict({**TINY, "noise_std_m": [own.sim.noise_std_m]}).runs()[0].sim_key
    # Another interpreter (another str hash seed) computes the same keys: they can name folders on disk.
    code = f"from tools.sweep import spec_from_dict; print(*[r.key for r in spec_from_dict({TINY!r}).runs()])"
    other = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                           env={**os.environ, "PYTHONHASHSEED": "12345"}, cwd=Path(__file__).resolve().parents[1])
    assert other.stdout.split() == [r.key for r in runs]


# ---------------------------------------------------------------- a tiny sweep
@pytest.mark.slow
def test_tiny_sweep_writes_table_summary_and_plots(tiny_sweep):
    out, result = tiny_sweep
    assert result.executed == 4 and not result.failures
    rows = read_table(out / "results.csv")
    assert [r["label"] for r in rows] == [r.label for r in spec_from_dict(TINY).runs()]
    assert _stable(rows) == _stable(result.rows)
    for row in rows:
        assert row["status"] == "ok" and row["error"] is None
        assert row["simulate_s"] > 0 and row["odometry_s"] > 0 and row["frames_per_s"] > 0
        assert row["numpy_version"] == np.__version__ and row["python_version"].startswith("3.")
        # The row's figures are the metrics of the run's poses against the simulator's ground truth.
        T_gt = read_kitti_poses(out / "sequences" / row["sim_key"] / "poses.txt")
        T_est = read_kitti_poses(out / "runs" / row["key"] / "poses.txt")
        expect = evaluate_trajectory(T_gt, T_est).to_dict()
        for metric in ("ate_rmse_m", "ate_aligned_rmse_m", "rpe_t_rmse_m", "rpe_r_rmse_deg"):
            assert row[metric] == pytest.approx(expect[metric], rel=1e-12)
        assert 0 < row["ate_rmse_m"] < 0.1  # 4 frames of a few cm each
        assert (out / "runs" / row["key"] / "diagnostics.csv").is_file()
    # One simulated sequence per noise level, shared by both variants.
    assert sorted(p.name for p in (out / "sequences").iterdir() if p.is_dir()) == sorted({r["sim_key"] for r in rows})
    summary = (out / "summary.md").read_text()
    assert summary.count("| city | vlp16 |") == 4
    png = (out / "plots" / "city.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000


@pytest.mark.slow
def test_resume_skips_finished_runs_and_redoes_a_half_written_one(tiny_sweep, tmp_path):
    src, first = tiny_sweep
    out = tmp_path / "copy"
    shutil.copytree(src, out)
    store = Store(out)
    stamps = {r["key"]: store.result_path(r["key"]).stat().st_mtime_ns for r in first.rows}
    again = run_sweep(spec_from_dict(TINY), out, InlineExecutor(), report=False)
    assert again.executed == 0 and again.plan.skipped == 4
    assert {k: store.result_path(k).stat().st_mtime_ns for k in stamps} == stamps
    # A crash half-way: the run's folder has artifacts but no result.json; a killed simulation left debris.
    victim = first.rows[3]["key"]
    store.result_path(victim).unlink()
    (store.run_dir(victim) / "poses.txt").write_text("garbage\n")
    debris = out / "sequences" / ".deadbeef.partial-99999"
    debris.mkdir()
    plan = plan_sweep(spec_from_dict(TINY), store)
    assert (plan.partial, [r.key for r in plan.todo], plan.sims) == (1, [victim], [])
    resumed = run_sweep(spec_from_dict(TINY), out, InlineExecutor(), report=False)
    assert resumed.executed == 1 and not debris.exists()
    assert _stable(resumed.rows) == _stable(first.rows)  # redone in this process: the same figures
    assert resumed.rows[3]["sim_cached"] is True  # its sequence was reused, not simulated again
    assert store.state(victim) == "ok"


@pytest.mark.slow
def test_a_failed_run_is_recorded_and_the_others_complete(tmp_path):
    spec = spec_from_dict({**TINY, "noise_std_m": [0.01], "variants": ["bl", "broken"],
                           "commands": {"broken": "echo cannot read {sequence} >&2; exit 3 # {out}"}})
    result = run_sweep(spec, tmp_path / "s", InlineExecutor(), report=False)
    ok, failed = result.rows
    assert ok["status"] == "ok" and ok["ate_rmse_m"] is not None
    assert failed["status"] == "failed" and failed["ate_rmse_m"] is None
    assert "status 3" in failed["error"] and "cannot read" in failed["error"]
    assert read_table(tmp_path / "s" / "results.csv")[1]["error"] == failed["error"]
    # A failed simulation fails its runs with the reason, and the sweep still completes.
    too_long = spec_from_dict({**TINY, "noise_std_m": [0.01], "start_s": 95.0})
    rows = run_sweep(too_long, tmp_path / "t", InlineExecutor(), report=False).rows
    assert [r["status"] for r in rows] == ["failed", "failed"]
    assert all("simulation" in r["error"] and "room for" in r["error"] for r in rows)
    # Failed runs are redone by the next sweep (unless told not to).
    assert len(plan_sweep(too_long, Store(tmp_path / "t")).todo) == 2
    assert len(plan_sweep(too_long, Store(tmp_path / "t"), retry_failed=False).todo) == 0


@pytest.mark.slow
def test_a_sweep_in_memory_gives_the_rows_of_one_on_disk_and_writes_no_sequence(tiny_sweep, tmp_path):
    _, disk = tiny_sweep
    memory = run_sweep(spec_from_dict({**TINY, "sequences": "memory"}), tmp_path / "m", InlineExecutor(),
                       report=False)
    assert not memory.failures and not (tmp_path / "m" / "sequences").exists()
    assert [r["key"] for r in memory.rows] == [r["key"] for r in disk.rows]
    for a, b in zip(memory.rows, disk.rows, strict=True):
        # the same scans, rings and point times reach the odometry (the folder's text files round the sweep
        # start times and true poses at 1e-14): the same poses to rounding, so the same figures
        assert np.allclose(read_kitti_poses(tmp_path / "m" / "runs" / a["key"] / "poses.txt"),
                           read_kitti_poses(tiny_sweep[0] / "runs" / b["key"] / "poses.txt"), rtol=0, atol=1e-12)
        for metric in ("ate_rmse_m", "ate_aligned_rmse_m", "rpe_t_rmse_m", "rpe_r_rmse_deg"):
            assert a[metric] == pytest.approx(b[metric], rel=1e-6, abs=1e-12), metric
    # a path too short fails the runs as a failed simulation, as on disk
    rows = run_sweep(spec_from_dict({**TINY, "sequences": "memory", "noise_std_m": [0.01], "start_s": 95.0}),
                     tmp_path / "t", InlineExecutor(), report=False).rows
    assert all(r["status"] == "failed" and "simulation" in r["error"] and "room for" in r["error"] for r in rows)


@pytest.mark.slow
def test_dask_local_cluster_gives_the_same_rows_as_local_processes(tiny_sweep, tmp_path):
    distributed = pytest.importorskip("distributed")
    _, local = tiny_sweep  # two local worker processes
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as c:
        dask = run_sweep(spec_from_dict(TINY), tmp_path / "dask", DaskExecutor(c.scheduler_address), report=False)
    assert not dask.failures
    assert _stable(dask.rows) == _stable(local.rows)


# ---------------------------------------------------------------- regress
SUITE = {"name": "suite", "scenes": ["city"], "sensors": ["vlp16"], "noise_std_m": [0.02], "variants": ["bl", "salo"],
         "frames": 4}


def _regress(capsys, *args) -> tuple[int, str]:
    code = cli.main(["regress", "--workers", "0", *map(str, args)])
    out = capsys.readouterr()
    return code, out.out + out.err


@pytest.mark.slow
def test_regress_passes_against_its_own_baseline_and_fails_when_an_error_grows(tmp_path, capsys):
    suite, baseline = tmp_path / "suite.yaml", tmp_path / "baseline.json"
    suite.write_text(yaml.safe_dump(SUITE))
    common = ("--suite", suite, "--baseline", baseline, "--out", tmp_path / "out", "--keep-sequences")
    code, text = _regress(capsys, *common)
    assert code == 2 and "no baseline file" in text
    code, text = _regress(capsys, *common, "--update")
    assert code == 0 and "wrote the baseline" in text
    doc = json.loads(baseline.read_text())
    assert set(doc["runs"]) == {"city/seed0/vlp16/noise0.02/bl", "city/seed0/vlp16/noise0.02/salo"}
    code, text = _regress(capsys, *common)
    assert code == 0 and "regress PASSED" in text
    # Pretend the baseline was better: the current figure now exceeds baseline + tolerance.
    label = "city/seed0/vlp16/noise0.02/salo"
    current = doc["runs"][label]["ate_aligned_rmse_m"]
    doc["runs"][label]["ate_aligned_rmse_m"] = current / 10
    doc["tolerance"]["floors"]["ate_aligned_rmse_m"] = current / 100
    baseline.write_text(json.dumps(doc))
    code, text = _regress(capsys, *common)
    assert code == 1 and "regress FAILED" in text
    line = next(t for t in text.splitlines() if "grew" in t)
    assert label in line and "ate_aligned_rmse_m" in line
    assert f"{current:.6g} now" in line and f"baseline {current / 10:.6g}" in line
    # A changed suite is not compared with a baseline written for another one.
    suite.write_text(yaml.safe_dump({**SUITE, "frames": 5}))
    code, text = _regress(capsys, *common)
    assert code == 2 and "another suite" in text


@pytest.mark.slow
def test_regress_guards_a_method_and_fails_a_copy_of_the_truth_and_a_constant_velocity_guess(tmp_path, capsys):
    # The user's real method: our odometry's command line, run on the staged folder (no ground truth in it).
    real = f"{sys.executable} -m tools.cli odometry {{sequence}} --variant bl --out {{out}}"
    cheat = "cp {sequence}/poses.txt {out}"
    guess = tmp_path / "constant_velocity.py"  # 0.5 m per frame straight ahead, whatever the scans say
    guess.write_text(textwrap.dedent("""
        import sys
        from pathlib import Path
        import numpy as np
        scans, out = Path(sys.argv[1]), sys.argv[2]
        n = len(list(scans.glob("*.bin")))
        poses = np.tile(np.eye(4)[:3].ravel(), (n, 1))
        poses[:, 3] = 0.5 * np.arange(n)
        np.savetxt(out, poses, fmt="%.9f")
    """))
    suite = tmp_path / "suite.yaml"
    suite.write_text(yaml.safe_dump({**SUITE, "frames": 6, "speed_m_s": 8.0, "start_s": 4.0}))
    common = ("--suite", suite, "--out", tmp_path / "out", "--keep-sequences", "--baseline-dir", tmp_path / "b",
              "--method", "mine")
    code, text = _regress(capsys, *common, "--odometry-command", real)
    assert code == 2 and "no baseline file for method 'mine'" in text and "--update" in text
    code, text = _regress(capsys, *common, "--odometry-command", real, "--update")
    assert code == 0, text
    doc = json.loads((tmp_path / "b" / "suite" / "mine.json").read_text())
    (label, figures), = doc["runs"].items()
    assert doc["method"] == "mine" and label == "city/seed0/vlp16/noise0.02/mine"
    # The simulator's truth: 6 frames at 8 m/s with 2 cm noise are registered to a few cm.
    assert figures["ate_aligned_rmse_m"] < 0.05
    code, text = _regress(capsys, *common, "--odometry-command", real)
    assert code == 0 and "regress mine PASSED" in text
    code, text = _regress(capsys, *common, "--odometry-command", cheat)
    assert code == 1 and "regress mine FAILED" in text and "No such file" in text
    code, text = _regress(capsys, *common, "--odometry-command", f"{sys.executable} {guess} {{scans}} {{out}}")
    assert code == 1 and "regress mine FAILED" in text and "grew" in text
    # A baseline written by the truth-copying command cannot exist: the run fails, nothing is written.
    code, text = _regress(capsys, *common[:-2], "--method", "cheat", "--odometry-command", cheat, "--update")
    assert code == 2 and "cannot write a baseline from failed runs" in text
    assert not (tmp_path / "b" / "suite" / "cheat.json").exists()


def test_regress_names_the_flag_that_fixes_a_wrong_method_or_command(tmp_path, capsys):
    suite = tmp_path / "suite.yaml"
    suite.write_text(yaml.safe_dump(SUITE))
    baseline = tmp_path / "mine.json"
    baseline.write_text(json.dumps({"method": "mine", "suite": {}, "runs": {}}))
    common = ("--suite", suite, "--out", tmp_path / "out")
    code, text = _regress(capsys, *common, "--method", "other", "--baseline", baseline, "--odometry-command",
                          "run {scans} {out}")
    assert code == 2 and "give --method mine" in text and "--update" not in text
    code, text = _regress(capsys, *common, "--baseline", baseline)
    assert code == 2 and "give --method mine" in text and "--update" not in text
    code, text = _regress(capsys, *common, "--method", "x", "--odometry-command", "true")
    assert code == 2 and "--odometry-command 'true' has no {out} and {scans}" in text
    assert "commands." not in text
    code, text = _regress(capsys, *common, "--odometry-command", "run {scans} {out}")
    assert code == 2 and "needs one --method NAME" in text
    code, text = _regress(capsys, *common, "--method", "nope")
    assert code == 2 and "unknown method 'nope'" in text and "peers: kiss-icp" in text
    code, text = _regress(capsys, *common, "--method", "salo", "--fields", "ring,normal")
    assert code == 2 and "'normal' is the simulator's ground truth" in text


def test_read_table_keeps_text_columns_as_text(tmp_path):
    # run keys are hex: some look like numbers; versions like "2.0" must stay text too
    path = tmp_path / "results.csv"
    path.write_text("key,sim_key,numpy_version,seed,t_err_pct,sim_cached\n"
                    "1234e56789012345,0123456789012345,2.0,3,0.25,true\n")
    (row,) = read_table(path)
    assert row["key"] == "1234e56789012345" and row["sim_key"] == "0123456789012345"
    assert row["numpy_version"] == "2.0"
    assert row["seed"] == 3 and row["t_err_pct"] == 0.25 and row["sim_cached"] is True
