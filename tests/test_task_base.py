"""The Task base and the typed settings: flags made from the fields, presets, settings
saved in progress.json and read back (also from older files), the one registry."""
from __future__ import annotations

import dataclasses
import json
import os
import re
from typing import Optional

import pytest

from pilco.tasks import TASKS, build_parser, get_task, open_run
from pilco.tasks.base import Task
from pilco.tasks.settings import (RunSettings, parse_settings, positive_int, setting,
                                  settings_from_dict, settings_to_dict, task_settings)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@task_settings(episodes=6, output="runs/toy-seed{seed}")
class ToySettings(RunSettings):
    width: float = setting(0.5, "a width [m]")
    steps: int = setting(3, "some steps", kind=positive_int)
    mode: str = setting("a", "a choice", choices=("a", "b"))
    switch: bool = setting(False, "a switch")
    keep: bool = setting(True, "a switch that is on", negatable=True)
    corner: Optional[tuple] = setting(None, "a point", kind=float, nargs=2,
                                      metavar=("X", "Y"))
    derived: int = setting(0, "set by the task", flag=False)


PRESETS = {"wide": {"width": 2.0, "horizon": 100}}


def parse(argv):
    return parse_settings(ToySettings, argv, presets=PRESETS)


def test_every_field_is_one_flag_with_its_default_in_the_help():
    parser = build_parser_of_toy()
    flags = {a.dest: a for a in parser._actions if a.dest != "help"}
    fields = {f.name for f in dataclasses.fields(ToySettings)} - {"derived"}
    assert set(flags) == fields
    assert flags["width"].option_strings == ["--width"]
    assert flags["steps"].option_strings == ["--steps"]
    assert "(default 0.5)" in flags["width"].help and "(default 6)" in flags["episodes"].help
    assert flags["keep"].option_strings == ["--keep", "--no-keep"]
    # the inherited field took the new default, kept its help and its reading
    assert ToySettings().episodes == 6 and RunSettings().episodes == 4
    assert flags["episodes"].help.startswith("total episodes")


def build_parser_of_toy():
    from pilco.tasks.settings import build_parser as settings_parser

    return settings_parser(ToySettings, "toy", PRESETS)


def test_flags_are_read_typed_and_bad_values_are_usage_errors(capsys):
    s = parse(["--width", "0.25", "--steps", "4", "--mode", "b", "--switch", "--no-keep",
               "--corner", "1", "2", "--seed", "7"])
    assert (s.width, s.steps, s.mode, s.switch, s.keep, s.corner) == (
        0.25, 4, "b", True, False, (1.0, 2.0))
    assert s.output == "runs/toy-seed7"  # {seed} filled in
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.width = 1.0  # frozen
    for argv, message in ((["--steps", "0"], "--steps: must be at least 1"),
                          (["--mode", "c"], "--mode: invalid choice"),
                          (["--width", "x"], "--width: invalid float value")):
        with pytest.raises(SystemExit) as stop:
            parse(argv)
        assert stop.value.code == 2 and message in capsys.readouterr().err


def test_a_default_given_to_a_setting_no_base_has_is_refused():
    with pytest.raises(TypeError, match="no inherited settings"):
        task_settings(nonsense=1)(type("Bad", (RunSettings,), {}))


def test_presets_sit_between_the_defaults_and_the_flags_given(tmp_path):
    assert parse([]).width == 0.5
    s = parse(["--preset", "wide", "--horizon", "20"])
    assert (s.width, s.horizon, s.preset) == (2.0, 20, "wide")
    # a resumed run keeps its preset and settings; flags given again still win
    run = tmp_path / "run"
    run.mkdir()
    (run / "progress.json").write_text(json.dumps({"settings": settings_to_dict(s)}))
    resumed = parse(["--resume", str(run), "--episodes", "9"])
    assert (resumed.width, resumed.horizon, resumed.episodes, resumed.preset) == (
        2.0, 20, 9, "wide")
    assert resumed.output == str(run)
    with pytest.raises(ValueError, match="sets unknown settings"):
        parse_settings(ToySettings, [], presets={"bad": {"nope": 1}})


def test_an_older_run_file_with_missing_removed_and_list_values_resumes(tmp_path):
    run = tmp_path / "old"
    run.mkdir()
    # the settings of older versions sat under "args"; this one lacks "width" (added
    # since), holds "gone" (removed since) and a list where the field has a tuple
    (run / "progress.json").write_text(json.dumps({"args": {
        "steps": 5, "gone": 1, "corner": [0.5, 0.25], "output": "elsewhere"}}))
    s = parse(["--resume", str(run)])
    assert (s.steps, s.width, s.corner, s.output) == (5, 0.5, (0.5, 0.25), str(run))
    with pytest.raises(SystemExit):
        parse(["--resume", str(tmp_path / "missing")])


def test_a_saved_single_value_of_a_setting_that_now_takes_several_is_a_tuple():
    """The gym task's start variance was one number; runs saved then resume with it as
    the one-element tuple the per-dimension setting reads."""
    from pilco.tasks.gym import GymSettings

    old = settings_from_dict(GymSettings, {"start_var": 0.001, "noise_variance": 0.0,
                                           "widths": [0.5, 0.5, 1.0], "output": "x"})
    assert old.start_var == (0.001,) and old.noise_variance == (0.0,)
    assert old.widths == (0.5, 0.5, 1.0) and old.angles is None  # None stays unset


def test_settings_round_trip_through_a_real_runs_progress_file(tmp_path):
    """A run written by a task stores its settings; reading them back gives the same
    settings object (the resume precedence keeps every saved value)."""
    task = get_task("cartpole")
    out = str(tmp_path / "run")
    settings = task.parse(["--episodes", "1", "--horizon", "5", "--cost-width", "0.3",
                           "--quiet", "--no-render", "--no-figures", "--output", out])
    exp = task.experiment(settings)
    task.run(exp, settings)
    exp.close()
    with open(os.path.join(out, "progress.json"), encoding="utf-8") as f:
        saved = json.load(f)["settings"]
    assert saved == settings_to_dict(settings)
    resumed = task.parse(["--resume", out])
    assert resumed == dataclasses.replace(settings, resume=out)
    assert settings_from_dict(type(settings), saved) == settings
    reopened = open_run(out)
    try:
        assert reopened.config == task.config(resumed)
    finally:
        reopened.close()


def test_the_registry_names_every_task_once():
    for name in TASKS:
        task = get_task(name)
        assert isinstance(task, Task) and task.name == name
        assert issubclass(task.settings, RunSettings)
        parser = build_parser(name)
        dests = {a.dest for a in parser._actions}
        flagged = {f.name for f in dataclasses.fields(task.settings)
                   if f.metadata.get("pilco_flag", {}).get("flag", True)}
        assert flagged - {"preset"} <= dests
        for preset in task.presets.values():  # presets name real settings
            assert set(preset) <= {f.name for f in dataclasses.fields(task.settings)}
    with pytest.raises(ValueError, match="unknown task 'nope'; choose one of cartpole"):
        get_task("nope")


def test_no_task_name_is_spelled_outside_the_tasks_package():
    """The sweep, the diagnosis and the experiment layer find tasks through the registry;
    a task's name as a string literal elsewhere in the library is a second registry."""
    pattern = re.compile(r"""["'](%s)["']""" % "|".join(TASKS))
    found = []
    for folder, _, files in os.walk(os.path.join(ROOT, "pilco")):
        if os.path.join("pilco", "tasks") in folder:
            continue
        for name in files:
            if name.endswith(".py"):
                path = os.path.join(folder, name)
                with open(path, encoding="utf-8") as f:
                    for number, line in enumerate(f, 1):
                        if pattern.search(line):
                            found.append(f"{os.path.relpath(path, ROOT)}:{number}: {line.strip()}")
    assert not found, "\n".join(found)
