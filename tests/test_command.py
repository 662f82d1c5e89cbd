"""The ``pilco`` command: its commands, their help, a usage error, a tiny cart-pole run.

The command runs as ``python -m pilco`` (what the ``pilco`` console script runs; the
script itself exists only once the package is installed), with the repository's pilco
first on the path.
"""
from __future__ import annotations

import ast
import json
import os
import subprocess
import sys

import pytest

from pilco import command
from pilco.tasks import TASKS

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def pilco(*argv, timeout=300):
    """``python -m pilco ARGV`` run to its end (text output)."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [ROOT, *filter(None, [os.environ.get("PYTHONPATH")])]), OMP_NUM_THREADS="1")
    env.pop("TF_CPP_MIN_LOG_LEVEL", None)  # the command's own default
    return subprocess.run([sys.executable, "-m", "pilco", *argv], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=timeout)


def test_setup_declares_the_console_script():
    tree = ast.parse(open(os.path.join(ROOT, "setup.py"), encoding="utf-8").read())
    call = next(node for node in ast.walk(tree)
                if isinstance(node, ast.Call) and getattr(node.func, "id", "") == "setup")
    entry_points = ast.literal_eval(next(k.value for k in call.keywords
                                         if k.arg == "entry_points"))
    assert entry_points == {"console_scripts": ["pilco = pilco.command:main"]}
    assert callable(command.main)


@pytest.mark.parametrize("argv, names", [
    (["--help"], ["run TASK", "sweep TASK", "diagnose RUN_DIR", "tasks"]),
    (["-h"], ["run TASK", "sweep TASK", "diagnose RUN_DIR", "tasks"]),
    (["run", "--help"], ["pilco run TASK", *TASKS]),
    (["run", "cartpole", "--help"], ["--episodes", "--horizon", "--policy-iters", "--resume"]),
    (["sweep", "--help"], ["usage: pilco sweep TASK", "--seeds", "--grid", "--set",
                           "--address", "--cpus-per-run", "pilco sweep cartpole"]),
    (["diagnose", "--help"], ["run_dir", "--episode", "--restarts", "--threads",
                              "--log-level"]),
    (["tasks", "--help"], ["usage: pilco tasks"]),
])
def test_every_command_has_help(argv, names):
    done = pilco(*argv)
    assert done.returncode == 0, done.stderr
    for name in names:
        assert name in done.stdout


def test_tasks_lists_the_task_names():
    done = pilco("tasks")
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == list(TASKS)


@pytest.mark.parametrize("argv, message", [
    ([], "pilco: error: no command given; choose one of run, sweep, diagnose, tasks"),
    (["bogus"], "pilco: error: unknown command 'bogus'; choose one of run, sweep, "
                "diagnose, tasks"),
    (["run"], "pilco run: error: no task given"),
    (["run", "nope"], "pilco run: error: unknown task 'nope'; choose one of "
                      + ", ".join(TASKS)),
    (["tasks", "extra"], "pilco tasks: error: unexpected argument(s): extra"),
    (["sweep", "nope"], "pilco sweep: error: unknown task 'nope'"),
    (["diagnose"], "the following arguments are required: run_dir"),
    (["diagnose", "somewhere", "--log-level", "loud"], "invalid log_level value: 'loud'"),
])
def test_usage_errors_exit_2_with_a_message(argv, message, capsys, monkeypatch):
    """In this process (TensorFlow's start-up left alone: the subprocess tests cover it)."""
    monkeypatch.setattr(command, "quiet_tensorflow", lambda: None)
    try:
        status = command.main(argv)
    except SystemExit as stop:  # argparse's error
        status = stop.code
    assert status == 2
    captured = capsys.readouterr()
    assert message in captured.err
    assert captured.out == ""


def test_run_cartpole_writes_its_summary(tmp_path):
    out = tmp_path / "cartpole"
    done = pilco("run", "cartpole", "--episodes", "2", "--horizon", "5", "--policy-iters",
                 "2", "--model-iters", "5", "--basis-functions", "3", "--quiet",
                 "--no-render", "--no-figures", "--output", str(out))
    assert done.returncode == 0, done.stderr[-3000:]
    with open(out / "summary.json", encoding="utf-8") as fh:
        summary = json.load(fh)
    assert summary["task"] == "cartpole" and summary["complete"] is True
    assert [e["episode"] for e in summary["episodes"]] == [1, 2]
    assert "Could not find cuda drivers" not in done.stderr  # TensorFlow started quietly
