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
    (["--env", "Pendulum-v1", "--start-var", "1", "2"], "--start-var: one number or 3"),
    (["--env", "Pendulum-v1", "--noise-variance", "1", "2"], "--noise-variance: one number"),
    (["--env", "Pendulum-v1", "--widths", "1", "1", "inf", "--success-dims", "2"],
     "distance dimensions [2]: each must be one of 0-2 with a finite width"),
    (["--env", "Pendulum-v1", "--state-dims", "0", "3"],
     "state dimensions [0, 3]: each once, of the observation's 0-2"),
    (["--env", "Pendulum-v1", "--linear", "1", "2"], "--linear: 3 weights"),
    (["--env", "Pendulum-v1", "--penalties", "1", "2"], "--penalties: triples"),
    (["--env", "Pendulum-v1", "--penalties", "3", "0", "1"], "the dimension 3.0 must be"),
    (["--env", "Pendulum-v1", "--penalties", "1", "0", "0"], "must be a positive number"),
    (["--env", "Pendulum-v1", "--widths", "inf", "--success", "advance"],
     "the reward has nothing to reward"),
    (["--env", "Pendulum-v1", "--success", "advance"],
     "progress_key 'x_position': the environment's info has no such number"),
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
        assert args.env == PRESETS[name]["env"]
        assert args.success in ("survive", "hold", "reach", "advance")
    car = GYM.read_settings(["--preset", "mountain-car", "--output", "x"])
    assert (car.horizon, car.action_repeat, car.start_var) == (25, 5, (0.0065, 4.5e-5))


def test_the_pendulum_presets_success_is_the_pendulum_tasks_angle():
    # hold within 2√2 sin(0.15) widths on (cos θ, sin θ) is |θ| < 0.3 rad
    args = GYM.parse(["--preset", "pendulum", "--output", "x"])
    env = GYM.make_env(args, GYM.config(args))
    try:
        for theta, inside in ((0.29, True), (-0.29, True), (0.31, False), (3.0, False)):
            x = np.array([np.cos(theta), np.sin(theta), 5.0])  # the speed is not measured
            assert (env.distance(x) < args.success_distance) == inside
    finally:
        env.close()


def test_per_dimension_start_and_fixed_noise_and_the_reach_rule(tmp_path):
    # the mountain car: the goal ends the episode; reach measures the position only
    exp, summary = run(tmp_path, "--env", "MountainCarContinuous-v0", "--horizon", "10",
                       "--action-repeat", "5", "--target", "0.5", "0", "--widths", "0.16",
                       "0.03", "--start-var", "0.0065", "4.5e-5", "--noise-variance",
                       "6.5e-4", "0", "--success", "reach", "--success-dims", "0",
                       "--success-distance", "0.3125")
    assert np.allclose(np.diag(exp.agent.S_init), [0.0065, 4.5e-5])
    first, second = exp.agent.mgpr.models
    # the position's noise is fixed at the value given, the speed's learned
    assert not first.likelihood.variance.trainable and second.likelihood.variance.trainable
    assert float(first.likelihood.variance.numpy()) == pytest.approx(6.5e-4)
    env = exp.make_env()
    assert env.distance(np.array([0.46, 0.07])) == pytest.approx(0.04 / 0.16)
    assert exp.config.solved_rule == "reach" and exp.config.success_threshold == 0.3125
    assert summary["success"] == (min(summary["distances"][-1][1:]) < 0.3125)


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


def test_state_dims_keep_part_of_the_observation_and_the_model_its_first_steps(tmp_path):
    # Pendulum-v1's observation is [cos θ, sin θ, θ̇]: the state here is [θ̇, cos θ]
    exp, summary = run(tmp_path, "--env", "Pendulum-v1", "--horizon", "6",
                       "--state-dims", "2", "0", "--target", "0", "1", "--model-steps", "4")
    env = exp.make_env()
    x, _ = env.reset(seed=3)
    raw = env.unwrapped.state  # [θ, θ̇]
    assert x == pytest.approx([raw[1], np.cos(raw[0])]) and env.observation_space.shape == (2,)
    assert exp.agent.mgpr.num_outputs == 2
    X, Y = exp.training_data()
    # every step is kept in the data, the model learns from the first 4 of each episode
    with np.load(exp.store.data_path) as data:
        assert data["X"].shape == (12, 3)
    assert X.shape == (8, 3) and Y.shape == (8, 2)
    assert np.array_equal(X[4:], exp.episodes[1].transitions()[0][:4])


@pytest.mark.parametrize("preset, mujoco", [("mountain-car", False),
                                            ("inverted-double-pendulum", True)])
def test_a_preset_runs_end_to_end(preset, mujoco, tmp_path):
    # the preset's settings, only shorter: one random and one learned episode
    if mujoco:
        pytest.importorskip("mujoco")
    exp, summary = run(tmp_path, "--preset", preset, "--random-episodes", "1", "--horizon",
                       "12", "--planning-horizon", "8", "--policy-restarts", "1",
                       "--model-restarts", "1")
    steps = [e["steps"] for e in summary["episodes"]]
    assert len(steps) == 2 and all(1 <= n <= 12 for n in steps)
    D = len(PRESETS[preset]["target"])
    assert exp.agent.mgpr.num_outputs == D and exp.agent.horizon == 8
    assert np.allclose(np.diag(exp.agent.S_init),
                       np.broadcast_to(PRESETS[preset]["start_var"], (D,)))
    X, _ = exp.training_data()
    cap = PRESETS[preset].get("model_steps") or 12
    assert len(X) == sum(min(n, cap) for n in steps)


def test_the_swimmer_preset_rewards_speed_minus_joint_limits_and_measures_progress(tmp_path):
    """The swimmer preset (shortened): its reward is the forward speed minus a saturating
    bump at ±95° of each joint, with no target term; each episode's distances are what is
    left of the 1 m to swim (1 at the start, above 1 after swimming backwards), and
    success is that rest reaching 0."""
    pytest.importorskip("mujoco")
    import tensorflow as tf

    exp, summary = run(tmp_path, "--preset", "swimmer", "--random-episodes", "1",
                       "--horizon", "12", "--planning-horizon", "6", "--model-steps", "6",
                       "--policy-restarts", "1", "--model-restarts", "1")
    assert [e["steps"] for e in summary["episodes"]] == [12, 12]
    reward = exp.agent.reward
    x = np.array([[0.1, np.radians(95.0), -0.3, 0.4, 0.0, 0.0, 0.0, 0.0]])
    mean, _ = reward.moments(tf.constant(x), tf.zeros((8, 8), tf.float64))
    bumps = [np.exp(-10 * (x[0, d] - c) ** 2 / 2) for d in (2, 1)
             for c in (np.radians(95.0), -np.radians(95.0))]
    assert float(np.squeeze(mean)) == pytest.approx(0.4 - sum(bumps), rel=1e-9)
    for distances in summary["distances"]:
        assert distances[0] == 1.0 and min(distances) >= 0.0
    assert summary["success"] == (min(summary["distances"][-1][1:]) == 0.0)
    assert exp.config.solved_rule == "reach"
    X, _ = exp.training_data()
    assert len(X) == 12  # the first 6 steps of each episode
