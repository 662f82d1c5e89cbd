"""A seed names one run: the same task, seed and settings give the same run, every
distance equal, whether the run is alone with TensorFlow's default thread pools or
inside a sweep with one thread (a user reruns a sweep's failing seed alone to look at
it, and sweeps compare seeds before and after a change)."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from pilco import runtime

#: a short cart-pole run: one random and two learned episodes
ARGS = ["cartpole", "--seed", "2", "--episodes", "3", "--horizon", "20",
        "--basis-functions", "5", "--policy-iters", "8", "--model-iters", "30", "--quiet",
        "--no-render", "--no-figures"]


def _alone_environment():
    """This process's environment without any thread setting: TensorFlow's and the BLAS
    libraries' defaults, as a user's shell has them."""
    env = {k: v for k, v in os.environ.items() if k not in runtime.THREAD_VARIABLES}
    env.setdefault("TF_CPP_MIN_LOG_LEVEL", runtime.TF_LOG_LEVEL)
    return env


@pytest.mark.timeout(600)
def test_a_run_alone_and_inside_a_sweep_is_the_same_run(tmp_path):
    settings = {"alone": _alone_environment(), "sweep": runtime.thread_environment(1)}
    procs = {}
    for name, env in settings.items():  # side by side, as a sweep's runs
        out = tmp_path / name
        procs[name] = (out, subprocess.Popen(
            [sys.executable, "-m", "pilco.tasks", *ARGS, "--output", str(out)], env=env,
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True))
    summaries = {}
    for name, (out, proc) in procs.items():
        log, _ = proc.communicate(timeout=590)
        assert proc.returncode == 0, log[-3000:]
        summaries[name] = json.loads((out / "summary.json").read_text())
    alone, sweep = summaries["alone"], summaries["sweep"]
    assert len(alone["episodes"]) == 3
    # the two processes did run with other thread settings
    env_alone = alone["provenance"].get("environment", {})
    env_sweep = sweep["provenance"].get("environment", {})
    assert env_sweep.get("TF_NUM_INTEROP_THREADS") == "1"
    assert env_alone.get("TF_NUM_INTEROP_THREADS") != "1"
    assert alone["distances"] == sweep["distances"]  # every distance, bit for bit
    assert [e["cost"] for e in alone["episodes"]] == [e["cost"] for e in sweep["episodes"]]
    assert alone["solved_episodes"] == sweep["solved_episodes"]
