"""A seed names one run: the same short run in two processes, one with a run's own
thread settings (``pilco run`` alone: TensorFlow's inter-op pool on every CPU) and one
with a sweep's (:func:`pilco.runtime.thread_environment`, one thread), gives the same
distance at every step of every episode: the cart-pole, and the double pendulum of the
gym task (8 GP outputs, whose 36 output pairs rounded differently in two groups, as a
run alone on two CPUs split them before the grouping stopped following the CPUs,
:func:`pilco.moments.configured_groups`).

Before the runs turned off Grappler's arithmetic optimizer
(:func:`pilco.runtime.reproducible_arithmetic`) the cart-pole's command gave 4 different
results in 10 processes with the same settings; the comparison here is bitwise.
"""
from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from pilco.runtime import THREAD_VARIABLES, thread_environment

ROOT = Path(__file__).resolve().parents[1]

FLAGS = ["--quiet", "--no-render", "--no-figures"]
CARTPOLE = ["cartpole", "--seed", "2", "--episodes", "3", "--horizon", "20",
            "--basis-functions", "5", "--policy-iters", "8", "--model-iters", "30", *FLAGS]
#: 5 random and 2 learned episodes: the second learned one parted with two groups
DOUBLE_PENDULUM = ["gym", "--preset", "inverted-double-pendulum", "--seed", "0",
                   "--episodes", "7", "--horizon", "30", *FLAGS]
NO_MUJOCO = importlib.util.find_spec("mujoco") is None


def _start(run: list, output: Path, env: dict) -> subprocess.Popen:
    env = dict(env)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    return subprocess.Popen([sys.executable, "-m", "pilco.tasks", *run,
                             "--output", str(output)], env=env, cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def _alone_environment() -> dict:
    """This process's environment without any thread variable: a user's shell."""
    return {k: v for k, v in os.environ.items() if k not in THREAD_VARIABLES}


@pytest.mark.parametrize("run", [
    pytest.param(CARTPOLE, id="cartpole"),
    pytest.param(DOUBLE_PENDULUM, id="double-pendulum",
                 marks=pytest.mark.skipif(NO_MUJOCO, reason="needs mujoco"))])
def test_a_run_alone_and_the_same_run_in_a_sweeps_process_are_identical(run, tmp_path):
    alone = _alone_environment()
    swept = thread_environment(1, alone)
    assert swept["TF_NUM_INTEROP_THREADS"] == "1" and "TF_NUM_INTEROP_THREADS" not in alone
    runs = {"alone": _start(run, tmp_path / "alone", alone),
            "sweep": _start(run, tmp_path / "sweep", swept)}
    summaries = {}
    for name, process in runs.items():
        output, _ = process.communicate(timeout=600)
        assert process.returncode == 0, output[-3000:]
        summaries[name] = json.loads((tmp_path / name / "summary.json").read_text())
    a, b = summaries["alone"]["distances"], summaries["sweep"]["distances"]
    episodes = int(run[run.index("--episodes") + 1])
    assert len(a) == len(b) == episodes
    if run is CARTPOLE:
        assert all(len(x) == 21 for x in a)
    for episode, (x, y) in enumerate(zip(a, b)):
        assert len(x) == len(y) and x == y, (
            f"episode {episode + 1} parted: {max(abs(p - q) for p, q in zip(x, y))}")
