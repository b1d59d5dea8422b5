"""examples/ci: the workflow calls the script, the script runs salo regress --method, the baseline fits the suite.

The slow test runs the script end to end on a tiny suite: a baseline is written,
the stand-in method passes against it, and a copy of the truth fails.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
import yaml
from conftest import REPO

CI = REPO / "examples" / "ci"


def test_the_workflow_installs_caches_and_calls_the_script():
    flow = yaml.safe_load((CI / "github-actions.yml").read_text())
    (job,) = flow["jobs"].values()
    runs = "\n".join(step.get("run", "") for step in job["steps"])
    assert "pip install" in runs and "bash examples/ci/regress.sh" in runs
    cache = next(step for step in job["steps"] if str(step.get("uses", "")).startswith("actions/cache"))
    # salo regress --keep-sequences keeps them in OUT/sequences (the sweep store's layout)
    assert cache["with"]["path"] == "${{ env.SALO_OUT }}/sequences"
    env = job["env"]
    assert env["SALO_SUITE"] == "examples/ci/suite.yaml" and env["SALO_BASELINES"] == "examples/ci/baselines"
    assert "{sequence}" in env["SALO_COMMAND"] and "{out}" in env["SALO_COMMAND"]


def test_the_committed_baseline_is_the_stand_ins_on_the_committed_suite():
    from tools.sweep import load_spec
    from tools.sweep.regress import check_suite, method_baseline_path, method_suite_spec

    spec = method_suite_spec(["my-odometry"], load_spec(CI / "suite.yaml"), {"my-odometry": "x {scans} {out}"})
    path = method_baseline_path("my-odometry", spec.name, CI / "baselines")
    doc = json.loads(path.read_text())
    check_suite(doc, spec, str(path), "my-odometry")  # raises if the suite or the method differ
    assert len(doc["runs"]) == 2


@pytest.mark.slow
def test_the_script_writes_a_baseline_passes_the_stand_in_and_fails_a_copy_of_the_truth(tmp_path):
    suite = tmp_path / "suite.yaml"
    spec = yaml.safe_load((CI / "suite.yaml").read_text())
    suite.write_text(yaml.safe_dump({**spec, "scenes": ["city"], "frames": 4}))
    env = {**os.environ, "SALO": f"{sys.executable} -m tools.cli", "SALO_SUITE": str(suite),
           "SALO_BASELINES": str(tmp_path / "baselines"), "SALO_OUT": str(tmp_path / "out"), "SALO_WORKERS": "0",
           "SALO_COMMAND": f"{sys.executable} {CI / 'my_odometry.py'} {{sequence}} {{out}}",
           "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}

    def script(*args, **changes):
        return subprocess.run(["bash", str(CI / "regress.sh"), *args], cwd=tmp_path, env={**env, **changes},
                              capture_output=True, text=True, timeout=900)

    done = script("--update")
    assert done.returncode == 0, done.stdout + done.stderr
    assert (tmp_path / "baselines" / "ci-example" / "my-odometry.json").is_file()
    assert (tmp_path / "out" / "sequences").is_dir()  # what the workflow caches
    done = script()
    assert done.returncode == 0 and "regress my-odometry PASSED" in done.stdout, done.stdout + done.stderr
    done = script(SALO_COMMAND="cp {sequence}/poses.txt {out}")
    assert done.returncode == 1 and "regress my-odometry FAILED" in done.stdout
    assert script("--bogus").returncode == 2
