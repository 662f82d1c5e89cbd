"""A task defined outside the package: the README's "Extending" file, written into a
directory of its own and run, reloaded, diagnosed and swept as a user would
(``pilco run my_task:TASK``, ``pilco diagnose``, ``pilco sweep my_task:TASK``); and the
environment contract (``info["distance"]``) refused with one clear error."""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from pilco.experiment import (EnvironmentContractError, Experiment, ExperimentConfig,
                              FunctionHooks)
from pilco.models import PILCO
from pilco.tasks import get_task

ROOT = Path(__file__).resolve().parents[1]
SHORT = ["--episodes", "2", "--horizon", "8", "--basis-functions", "4", "--policy-iters", "3",
         "--model-iters", "10"]


def readme_task() -> str:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    return next(b for b in blocks if "class MyTask(Task)" in b)


@pytest.fixture(scope="module")
def user_dir(tmp_path_factory):
    """A directory outside the package holding the README's my_task.py."""
    directory = tmp_path_factory.mktemp("user")
    (directory / "my_task.py").write_text(readme_task(), encoding="utf-8")
    return directory


def pilco(*args, cwd, timeout=600):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}  # this checkout's pilco, not the file's
    return subprocess.run([sys.executable, "-m", "pilco", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=timeout)


def test_the_readmes_task_file_is_short_and_complete():
    code = [line for line in readme_task().splitlines()
            if line.strip() and not line.lstrip().startswith("#")]
    assert len(code) <= 50, f"the README's task file has {len(code)} lines of code"
    assert "TASK = MyTask()" in readme_task()


def test_its_flags_and_reference(user_dir, monkeypatch, capsys):
    monkeypatch.chdir(user_dir)
    monkeypatch.syspath_prepend(str(user_dir))
    task = get_task("my_task:TASK")
    assert task.reference == "my_task:TASK" and task.prog == "pilco run my_task:TASK"
    s = task.parse(["--max-torque", "1.5"])
    assert (s.max_torque, s.episodes, s.horizon) == (1.5, 6, 30)
    assert task.config(s).task == "my_task:TASK"
    with pytest.raises(SystemExit):
        task.parse(["--max-torque", "-1"])
    assert "--max-torque: must be positive" in capsys.readouterr().err


@pytest.mark.parametrize("name, error, problem", [
    ("my_task:NOPE", ValueError, "has no attribute 'NOPE'"),
    ("my_task:np", TypeError, "is a module, not an instance of pilco.tasks.base.Task"),
    ("no_such_module_xyz:TASK", ValueError, "cannot import 'no_such_module_xyz'"),
    ("my_task:", ValueError, "expected package.module:ATTRIBUTE"),
    ("my_tsak", ValueError, "unknown task 'my_tsak'; choose one of cartpole"),
])
def test_a_bad_reference_names_the_problem(user_dir, monkeypatch, name, error, problem):
    monkeypatch.chdir(user_dir)
    monkeypatch.syspath_prepend(str(user_dir))
    with pytest.raises(error, match=re.escape(problem)):
        get_task(name)


def test_a_bad_reference_is_one_usage_error(user_dir):
    result = pilco("run", "my_task:NOPE", cwd=user_dir, timeout=120)
    assert result.returncode == 2, result.stderr
    assert "has no attribute 'NOPE'" in result.stderr and "Traceback" not in result.stderr


def test_run_reload_diagnose_and_sweep(user_dir, monkeypatch):
    run = pilco("run", "my_task:TASK", "--output", "run", "--quiet", "--no-render",
                "--no-figures", *SHORT, cwd=user_dir)
    assert run.returncode == 0, run.stderr
    summary = json.loads((user_dir / "run" / "summary.json").read_text())
    assert summary["task"] == "my_task:TASK" and len(summary["episodes"]) == 2
    assert all(np.isfinite(d).all() for d in summary["distances"])  # the wrapper's distance

    # the agent, with the file's own reward class, in this process
    monkeypatch.syspath_prepend(str(user_dir))
    agent = PILCO.load(user_dir / "run" / "agent.npz")
    assert type(agent.reward).__name__ == "QuadraticReward"
    assert type(agent.reward).__module__ == "my_task"
    assert np.isfinite(agent.expected_return())

    diagnosis = pilco("diagnose", "run", "--restarts", "0", "--starts", "0", cwd=user_dir)
    assert diagnosis.returncode == 0, diagnosis.stderr
    report = json.loads((user_dir / "run" / "diagnosis.json").read_text())
    assert report["task"] == "my_task:TASK" and report["episode"] == 2
    assert "reopened from its saved agent" not in diagnosis.stderr  # through the task

    # a run whose task module is gone is diagnosed from its saved agent, said once
    shutil.copytree(user_dir / "run", user_dir / "orphan")
    progress = json.loads((user_dir / "orphan" / "progress.json").read_text())
    progress["config"]["task"] = "no_such_module_xyz:TASK"
    (user_dir / "orphan" / "progress.json").write_text(json.dumps(progress))
    orphan = pilco("diagnose", "orphan", "--restarts", "0", "--starts", "0", cwd=user_dir)
    assert orphan.returncode == 0, orphan.stderr
    assert orphan.stderr.count("reopened from its saved agent") == 1, orphan.stderr

    # the sweep's runs are processes of their own, started by Ray's workers
    sweep = pilco("sweep", "my_task:TASK", "--seeds", "0-1", "--num-cpus", "2",
                  "--output", "sweep", "--no-progress", "--no-figures", "--max-retries", "0",
                  "--", *SHORT, cwd=user_dir)
    assert sweep.returncode == 0, sweep.stderr
    report = json.loads((user_dir / "sweep" / "sweep.json").read_text())
    assert report["task"] == "my_task:TASK"
    assert [(r["seed"], r["status"]) for r in report["runs"]] == [(0, "finished"),
                                                                   (1, "finished")]


class NoDistance(gym.Env):
    """A point on a line whose info says nothing of the goal."""

    observation_space = gym.spaces.Box(-10.0, 10.0, (1,), np.float64)
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float64)

    def reset(self, seed=None, options=None):
        super().reset(seed=seed)
        self.steps = 0
        return np.zeros(1), {"note": "no distance"}

    def step(self, u):
        self.steps += 1
        return np.zeros(1), 0.0, False, False, {}


def test_an_env_without_the_distance_is_refused_before_its_first_step(tmp_path):
    env = NoDistance()
    cfg = ExperimentConfig(task="line", env_id="unused", seed=0, episodes=2, horizon=4)
    exp = Experiment(cfg, str(tmp_path / "run"), FunctionHooks(lambda data, starts: None,
                                                               lambda: env))
    with pytest.raises(EnvironmentContractError,
                       match=r"reports no task distance.*holds none of 'distance', "
                             r"'tip_distance' \(it holds \['note'\]\).*distance\(env, info\)"):
        exp.run()
    assert env.steps == 0
