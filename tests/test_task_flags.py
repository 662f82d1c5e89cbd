"""Every task refuses a bad numeric flag by name, as an argparse error (exit status 2),
before any environment, model or TensorFlow work starts; a resumed run keeps the settings
it was saved with, and a setting it lacks takes today's default."""
import json
import re

import pytest

from pilco.tasks import TASKS, get_task
from pilco.tasks.adaptation import ADAPTATION
from pilco.tasks.cartpole import CARTPOLE
from pilco.tasks.reacher import DAMAGED_REACHER, REACHER
from pilco.tasks.settings import settings_to_dict

PARSERS = {name: get_task(name).parse for name in TASKS}

# flags every task has (pilco.tasks.settings.RunSettings)
COMMON = [
    (["--seed", "-1"], "--seed: must be at least 0"),
    (["--episodes", "0"], "--episodes: must be at least 1"),
    (["--horizon", "ten"], "--horizon: expected an integer"),
    (["--random-episodes", "-2"], "--random-episodes: must be at least 1"),
    (["--basis-functions", "0"], "--basis-functions: must be at least 1"),
    (["--policy-iters", "-5"], "--policy-iters: must be at least 1"),
    (["--policy-iters-first", "0"], "--policy-iters-first: must be at least 1"),
    (["--policy-restarts", "0"], "--policy-restarts: must be at least 1"),
    (["--policy-restart-from", "0"], "--policy-restart-from: must be at least 1"),
    (["--policy-patience", "0"], "--policy-patience: must be at least 1"),
    (["--model-iters", "1.5"], "--model-iters: expected an integer"),
    (["--model-restarts", "0"], "--model-restarts: must be at least 1"),
    (["--max-data", "-100"], "--max-data: must be at least 0"),
]

# flags of one task
OWN = [
    ("cartpole", ["--cost-width", "0"], "--cost-width: must be positive"),
    ("cartpole", ["--noise-std", "-0.01"], "--noise-std: must be zero or positive"),
    ("cartpole", ["--hold-steps", "0"], "--hold-steps: must be at least 1"),
    ("pendulum", ["--substeps", "0"], "--substeps: must be at least 1"),
    ("pendulum", ["--max-action", "nan"], "--max-action: must be positive"),
    ("reacher", ["--render-size", "320", "-1"], "--render-size: must be at least 1"),
    ("adaptation", ["--damaged-episodes", "0"], "--damaged-episodes: must be at least 1"),
    ("adaptation", ["--healthy-episodes", "-1"], "--healthy-episodes: must be at least 0"),
    ("adaptation", ["--old-data-noise", "0"], "--old-data-noise: must be positive"),
    ("adaptation", ["--old-data-noise", "inf"], "--old-data-noise: must be positive"),
]


def refused(task, argv, capsys, tmp_path):
    with pytest.raises(SystemExit) as stop:
        PARSERS[task]([*argv, "--output", str(tmp_path)])
    assert stop.value.code == 2
    return capsys.readouterr().err


@pytest.mark.parametrize("task", sorted(PARSERS))
@pytest.mark.parametrize("argv, message", COMMON)
def test_common_flags_refuse_bad_values(task, argv, message, capsys, tmp_path):
    assert message in refused(task, argv, capsys, tmp_path)


@pytest.mark.parametrize("task, argv, message", OWN)
def test_task_flags_refuse_bad_values(task, argv, message, capsys, tmp_path):
    assert message in refused(task, argv, capsys, tmp_path)


@pytest.mark.parametrize("task", sorted(PARSERS))
def test_edge_values_are_accepted(task, tmp_path):
    """0 where 0 means something: all data (--max-data 0)."""
    args = PARSERS[task](["--max-data", "0", "--random-episodes", "1", "--seed", "0",
                          "--policy-iters-first", "1", "--output", str(tmp_path)])
    assert (args.max_data, args.random_episodes, args.policy_iters_first) == (0, 1, 1)


@pytest.mark.parametrize("task", sorted(PARSERS))
def test_the_loops_checks_are_the_flags_checks(task, capsys, tmp_path):
    """A setting is checked once, where it is declared (LoopSettings): what the loop
    would refuse, the command line refuses, naming it."""
    assert "--random-episodes: must be at least 1" in refused(
        task, ["--random-episodes", "0"], capsys, tmp_path)
    assert "max_data must be at least 2" in refused(task, ["--max-data", "1"], capsys,
                                                    tmp_path)


def test_cartpole_restarts_late_by_default_and_saved_runs_resume_with_their_settings(
        tmp_path):
    args = CARTPOLE.parse(["--output", str(tmp_path / "new")])
    config = CARTPOLE.config(args)
    # no restarts before episode 5, two runs per search there and one more in each
    # further episode while unsolved
    assert [config.policy_restarts_at(n, False) for n in (2, 4, 5, 6, 8)] == [1, 1, 2, 3, 5]
    assert config.policy_restarts_at(6, True) == 1
    # a saved run's settings win over the defaults; one it lacks takes today's default
    saved = tmp_path / "saved"
    saved.mkdir()
    old = {k: v for k, v in settings_to_dict(args).items() if k != "policy_restart_from"}
    old.update(policy_restarts=3, output=str(saved))
    (saved / "progress.json").write_text(json.dumps({"settings": old}))
    resumed = CARTPOLE.config(CARTPOLE.parse(["--resume", str(saved)]))
    assert (resumed.policy_restarts, resumed.policy_restart_from) == (3, 5)
    assert resumed.policy_restarts_at(2, False) == 1
    assert resumed.policy_restarts_at(5, False) == 3


def test_the_adaptation_down_weights_old_data_and_older_files_resume(tmp_path):
    args = ADAPTATION.parse(["--output", str(tmp_path / "new")])
    assert args.old_data_noise == 100.0
    assert ADAPTATION.parse(["--old-data-noise", "1"]).old_data_noise == 1.0
    # a progress.json of an older version holds the settings under "args", and may lack
    # settings added since (they take today's defaults) or hold removed ones (ignored)
    saved = tmp_path / "saved"
    saved.mkdir()
    old = {k: v for k, v in settings_to_dict(args).items() if k != "old_data_noise"}
    old.update(output=str(saved), healthy_episodes=2, removed_long_ago=True)
    (saved / "progress.json").write_text(json.dumps({"args": old}))
    resumed = ADAPTATION.parse(["--resume", str(saved)])
    assert (resumed.old_data_noise, resumed.healthy_episodes) == (100.0, 2)
    assert resumed.episodes == 1 + 2 + 4


def test_the_reacher_arms_stop_a_stalled_policy_search_and_the_others_do_not(tmp_path):
    """The reacher's policy searches (healthy and damaged arm, the adaptation) end once
    the predicted return grew by less than 1 % over 5 iterations; the paper-code preset
    runs every iteration; ``--policy-min-rel-improvement 0`` turns it off."""
    out = ["--output", str(tmp_path / "run")]

    def early_stop(args, damaged=False):
        config = (DAMAGED_REACHER if damaged else REACHER).config(args)
        return config.policy_early_stop_at(False), config.policy_patience

    assert early_stop(REACHER.parse(out)) == (0.01, 5)
    assert early_stop(DAMAGED_REACHER.parse(out), damaged=True) == (0.01, 5)
    assert early_stop(DAMAGED_REACHER.parse(["--preset", "paper-code", *out]),
                      damaged=True)[0] == 0.0
    # 0: a run never gains less than 0, so every iteration runs
    assert early_stop(REACHER.parse(["--preset", "paper-code", *out]))[0] == 0.0
    assert early_stop(REACHER.parse(["--policy-min-rel-improvement", "0", *out]))[0] == 0.0
    adapted = ADAPTATION.parse(out)
    assert (adapted.policy_min_rel_improvement, adapted.policy_patience) == (0.01, 5)


@pytest.mark.parametrize("changes, message", [
    # a task's own settings, by the rule of their declaration's kind or choices
    ({"cost_width": 0.0}, "cost_width must be a number > 0, got 0.0"),
    ({"start_std": -0.1}, "start_std must be a number >= 0, got -0.1"),
    ({"hold_steps": 2.5}, "hold_steps must be a whole number >= 1, got 2.5"),
    ({"squash": "tanh"}, "squash must be 'sat' or 'sin', got 'tanh'"),
    ({"risk_threshold": 1.0}, "risk_threshold must be a number between 0 and 1, got 1.0"),
    ({"risk_threshold": 0.0}, "risk_threshold must be a number between 0 and 1, got 0.0"),
    ({"cost_width": float("nan")}, "cost_width must be a number > 0"),
    # the loop's, with None where None is the default
    ({"policy_start_scale": -1.0}, "policy_start_scale must be a number >= 0 or None"),
    ({"policy_iters_first": 0}, "policy_iters_first must be a whole number >= 1 or None"),
    ({"policy_compiler": "jit"}, "policy_compiler must be 'graph' or 'xla'"),
    ({"seed": True}, "seed must be a whole number >= 0, got True"),
])
def test_settings_made_in_code_meet_their_declarations(changes, message, tmp_path):
    """Each setting is checked by what its declaration says (the same rule as its flag),
    for the loop's settings and a task's own alike, however the settings object is made."""
    import dataclasses

    args = CARTPOLE.parse(["--output", str(tmp_path)])
    with pytest.raises(ValueError, match=re.escape(message)):
        dataclasses.replace(args, **changes)
    # None where None is the default is "not set", and passes
    assert dataclasses.replace(args, policy_start_scale=None).policy_start_scale is None


def test_each_value_of_a_setting_of_several_is_checked(tmp_path):
    import dataclasses

    args = REACHER.parse(["--output", str(tmp_path)])
    assert dataclasses.replace(args, render_size=(64, 48)).render_size == (64, 48)
    with pytest.raises(ValueError, match=re.escape(
            "each of render_size must be a whole number >= 1, got (64, 0)")):
        dataclasses.replace(args, render_size=(64, 0))
