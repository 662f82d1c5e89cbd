"""The gym task: PILCO on a gymnasium environment named on the command line, end to end on
one MuJoCo and one classic-control environment, terminating episodes keeping their data,
and bad settings refused before any episode."""
from __future__ import annotations

import numpy as np
import pytest

from pilco.tasks.gym import GYM, PRESETS

SHORT = ["--episodes", "2", "--basis-functions", "4", "--policy-iters", "4",
         "--model-iters", "20", "--quiet", "--no-render", "--no-figures"]


def run(tmp_path, *flags):
    args = GYM.parse([*SHORT, "--output", str(tmp_path / "run"), *flags])
    exp = GYM.experiment(args)
    try:
        return exp, exp.run()
    finally:
        exp.close()


def test_inverted_pendulum_end_to_end_and_early_ends_keep_their_data(tmp_path):
    pytest.importorskip("mujoco")
    exp, summary = run(tmp_path, "--env", "InvertedPendulum-v5", "--horizon", "25")
    steps = [e["steps"] for e in summary["episodes"]]
    # the random episode lets the pole fall: the env terminates it early
    assert steps[0] < 25 and len(steps) == 2
    with np.load(exp.store.data_path) as data:
        assert data["X"].shape == (sum(steps), 5)  # 4 states + 1 action, every step kept
    assert summary["task"] == "gym" and summary["success"] == (steps[-1] == 25)
    assert exp.config.solved_rule == "survive" and exp.config.hold_steps == 25


def test_pendulum_with_a_target_widths_an_angle_and_the_hold_rule(tmp_path):
    exp, summary = run(tmp_path, "--env", "Pendulum-v1", "--horizon", "15",
                       "--target", "1", "0", "0", "--widths", "0.5", "0.5", "inf",
                       "--action-repeat", "2", "--success", "hold", "--success-steps", "5",
                       "--success-distance", "0.4")
    assert [e["steps"] for e in summary["episodes"]] == [15, 15]
    env = exp.make_env()
    # the distance in cost widths, the speed left out of the cost
    x = np.array([0.5, 0.5, 7.0])
    assert env.distance(x) == pytest.approx(np.hypot(-0.5 / 0.5, 0.5 / 0.5))
    assert exp.agent.reward.W.numpy()[2, 2] == 0.0 and exp.agent.horizon == 15
    assert exp.config.solved_rule == "hold" and exp.config.success_threshold == 0.4


@pytest.mark.parametrize("flags, message", [
    (["--env", "NoSuchEnv-v0"], "cannot make the environment"),
    (["--env", "CartPole-v1"], "action space must be a one-dimensional Box"),
    (["--env", "Pendulum-v1", "--target", "1", "0"], "target must be 3 finite numbers"),
    (["--env", "Pendulum-v1", "--widths", "1", "2"], "widths must be one positive number or 3"),
    (["--env", "Pendulum-v1", "--angles", "5"], "--angles [5]: the state has dimensions 0-2"),
    (["--env", "Pendulum-v1", "--env-kwargs", "[1]"], "expected a JSON object"),
])
def test_bad_settings_are_usage_errors_before_any_episode(flags, message, tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:
        GYM.parse([*flags, "--output", str(tmp_path / "x")])
    assert stop.value.code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_the_presets_name_known_settings():
    for name in PRESETS:
        args = GYM.read_settings(["--preset", name, "--output", "x"])
        assert args.planning_horizon == 40 and args.success == "survive"


def test_a_gym_run_is_diagnosed_without_predicting_the_envs_end(tmp_path, capsys):
    pytest.importorskip("mujoco")
    import json

    from pilco.diagnose import main

    exp, _ = run(tmp_path, "--env", "InvertedPendulum-v5", "--horizon", "15")
    out = tmp_path / "d.json"
    assert main([exp.directory, "--restarts", "0", "--starts", "0", "--output", str(out),
                 "--log-level", "WARNING"]) == 0
    saved = json.loads(out.read_text())
    # the model predicts states, not when the env ends an episode: survival is not predicted
    assert saved["model"]["multi_step"]["pred_solved"] is None
    assert "predicted to solve: not predicted" in capsys.readouterr().out


def test_the_gym_task_never_renders(tmp_path):
    # an arbitrary env's renderer may need pygame, or MuJoCo beside TensorFlow: no frames
    args = GYM.parse(["--env", "Pendulum-v1", "--output", str(tmp_path / "r")])
    assert not args.no_render and GYM.config(args).render is False
