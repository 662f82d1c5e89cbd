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
    (["diagnose", "--help"], ["RUN_DIR", "--episode", "--restarts", "--threads",
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
    (["diagnose"], "the following arguments are required: RUN_DIR"),
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


# -- one tool: version, usage lines, one default format, examples that run -----------------
def test_version_is_the_package_version():
    from importlib import metadata

    import pilco as package

    try:
        expected = metadata.version("pilco")
    except metadata.PackageNotFoundError:
        expected = package.__version__
    for flag in ("--version", "-V"):
        done = pilco(flag)
        assert done.returncode == 0, done.stderr
        assert done.stdout == f"pilco {expected}\n"


def _helps():
    """``{command line: its --help text}`` of every command, each task's included."""
    from pilco.diagnose import cli as diagnose_cli
    from pilco.sweep import cli as sweep_cli
    from pilco.tasks import get_task

    helps = {"pilco --help": command.usage(),
             "pilco sweep --help": sweep_cli.build_parser().format_help(),
             "pilco diagnose --help": diagnose_cli.build_parser().format_help()}
    for name in TASKS:
        helps[f"pilco run {name} --help"] = get_task(name).parser().format_help()
    return helps


@pytest.mark.parametrize("module, argv", [
    ("pilco", ["--help"]), ("pilco", ["run", "--help"]), ("pilco", ["tasks", "--help"]),
    ("pilco.tasks", ["--help"]), ("pilco.tasks", ["cartpole", "--help"]),
    ("pilco.sweep", ["--help"]), ("pilco.diagnose", ["--help"]),
])
def test_every_usage_line_says_pilco(module, argv):
    """Also when a command runs as ``python -m pilco.tasks`` and the like."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [ROOT, *filter(None, [os.environ.get("PYTHONPATH")])]))
    done = subprocess.run([sys.executable, "-m", module, *argv], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("usage: pilco ")
    assert "python -m" not in done.stdout.split("\n\n")[0]


@pytest.mark.parametrize("line", list(_helps()))
def test_every_help_shows_defaults_one_way(line):
    """``(default X)`` at most once per flag; no default for a plain switch (off unless
    given) nor a None that means nothing; argparse's ``(default: X)`` nowhere."""
    import re

    text = _helps()[line]
    assert text.startswith("usage: pilco ")
    assert "(default:" not in text
    flat = " ".join(text.split())
    for shown in ("(default None)", "(default False)", "(default True)", "(default ())"):
        assert shown not in flat, f"{line}: {shown}"
    # one entry per flag: split the help at the lines that start a flag
    entries = re.split(r"\n  (?=-)", text)
    for entry in entries:
        assert entry.count("(default") <= 1, f"{line}: doubled default in {entry!r}"


def _examples(text):
    """The command lines under ``examples:`` in a help text."""
    lines = text.split("\nexamples:\n", 1)[1].splitlines()
    return [line.strip() for line in lines if line.startswith("  pilco ")]


def _every_example():
    return [(line, example) for line, text in _helps().items() for example in _examples(text)]


def test_every_help_has_examples():
    for line, text in _helps().items():
        assert _examples(text), f"{line}: no examples"


class _Reached(Exception):
    """The command parsed and checked its example and would now start its work."""


@pytest.mark.parametrize("line, example", _every_example(),
                         ids=[e for _, e in _every_example()])
def test_every_help_example_runs(line, example, tmp_path, monkeypatch, capsys):
    """Each example runs through ``pilco.command.main`` in this process up to the point
    where its work would start: every flag and value is parsed and checked (task flags,
    sweep settings against the task's parser, run directories), then the work itself (a
    run, Ray, a diagnosis) is replaced by a stop. The run directories an example names
    exist as saved runs (a ``progress.json``) in a scratch working directory."""
    import shlex

    from pilco.diagnose import cli as diagnose_cli
    from pilco.sweep import cli as sweep_cli
    from pilco.tasks.base import Task
    from pilco import runtime

    def reached(*_, **__):
        raise _Reached

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(command, "quiet_tensorflow", lambda: None)
    for module in (runtime, diagnose_cli, sweep_cli):
        monkeypatch.setattr(module, "configure_logging", lambda *a, **k: None)
    for module in (runtime, diagnose_cli):
        monkeypatch.setattr(module, "configure_threads", lambda *a, **k: None)
    monkeypatch.setattr(Task, "experiment", reached)
    monkeypatch.setattr(sweep_cli, "_sweep", reached)
    monkeypatch.setattr("pilco.tasks.open_run", reached)
    argv = shlex.split(example)
    assert argv[0] == "pilco"
    argv = argv[1:]
    run_dirs = [argv[i + 1] for i, a in enumerate(argv[:-1]) if a == "--resume"]
    if argv[0] == "diagnose":
        run_dirs.append(next(a for a in argv[1:] if not a.startswith("-")))
    for run_dir in run_dirs:
        os.makedirs(run_dir)
        with open(os.path.join(run_dir, "progress.json"), "w", encoding="utf-8") as fh:
            json.dump({"settings": {"seed": 3}}, fh)
    try:
        status = command.main(argv)
    except _Reached:
        status = "reached"
    except SystemExit as stop:
        status = stop.code
    captured = capsys.readouterr()
    assert status in ("reached", 0), f"{example} (from {line}): {status}\n{captured.err}"
    if argv[0] == "tasks":
        assert captured.out.splitlines() == list(TASKS)


@pytest.mark.parametrize("make", ["missing", "file", "empty", "corrupt", "foreign"])
def test_diagnose_a_missing_or_wrong_run_directory_in_one_line(make, tmp_path):
    """Exit status 2 and one line on stderr, no traceback."""
    run_dir = tmp_path / "run"
    if make == "file":
        run_dir.write_text("not a directory")
    elif make != "missing":
        run_dir.mkdir()
        if make == "corrupt":
            (run_dir / "progress.json").write_text("{broken")
        elif make == "foreign":
            (run_dir / "progress.json").write_text("{}")
    done = pilco("diagnose", str(run_dir))
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert lines[0].startswith(f"pilco diagnose: error: {run_dir}")
    assert done.stdout == ""


@pytest.mark.parametrize("progress, message", [
    ("{broken", "progress.json is not a run's (JSONDecodeError"),
    ("{}", "cannot reopen the run (KeyError: 'records')"),
])
def test_run_resuming_a_wrong_run_directory_says_so_without_a_traceback(progress, message,
                                                                        tmp_path):
    (tmp_path / "progress.json").write_text(progress)
    done = pilco("run", "cartpole", "--resume", str(tmp_path), "--quiet", "--no-render")
    assert done.returncode == 2
    assert "Traceback" not in done.stderr
    assert f"pilco run cartpole: error: --resume {tmp_path}: {message}" in done.stderr
