"""The multi-task reacher: targets in the state, training targets in turn, the held-out
test, a tiny run end to end."""
from __future__ import annotations

import json
import os

import numpy as np
import pytest

from pilco.tasks.reacher_multi import (CONTEXT, REACHER_MULTI, TEST_STREAM, TRAIN_STREAM,
                                       draw_targets, start_cov)

pytest.importorskip("mujoco")


def test_training_and_test_targets_are_drawn_apart_in_the_cube():
    s = REACHER_MULTI.parse(["--seed", "3", "--training-targets", "5", "--test-targets", "7"])
    train = REACHER_MULTI.targets(s, TRAIN_STREAM, s.training_targets)
    test = REACHER_MULTI.targets(s, TEST_STREAM, s.test_targets)
    assert train.shape == (5, 3) and test.shape == (7, 3)
    centre = np.array([1.2, 0.38, 0.38])
    assert np.all(np.abs(train - centre) <= 0.15) and np.all(np.abs(test - centre) <= 0.15)
    assert not np.any(np.all(np.isclose(train[:, None], test[None]), axis=2))  # held out
    np.testing.assert_array_equal(train, draw_targets(3, 5, 0.15, centre, TRAIN_STREAM))
    assert not np.array_equal(train, draw_targets(4, 5, 0.15, centre, TRAIN_STREAM))


def test_the_state_holds_the_target_and_each_episode_runs_on_its_training_target():
    from pilco.envs import FETCH_ID, TargetInState
    from pilco.experiment import make_env

    env = TargetInState(make_env(FETCH_ID, {}))
    obs, _ = env.reset(seed=0, options={"target": [1.1, 0.3, 0.45]})
    assert obs.shape == (13,) and env.observation_space.shape == (13,)
    np.testing.assert_array_equal(obs[list(CONTEXT)], [1.1, 0.3, 0.45])
    obs, *_ = env.step(np.zeros(7))
    np.testing.assert_array_equal(obs[list(CONTEXT)], [1.1, 0.3, 0.45])  # constant
    with pytest.raises(TypeError, match="Fetch reacher"):
        TargetInState(make_env("pilco/CartPoleSwingUp-v0", {}))
    s = REACHER_MULTI.parse(["--training-targets", "3"])
    options = REACHER_MULTI.hooks(s, REACHER_MULTI.config(s), env).reset_options
    train = REACHER_MULTI.targets(s, TRAIN_STREAM, 3)
    for number, k in ((1, 0), (2, 1), (3, 2), (4, 0), (12, 2)):
        np.testing.assert_array_equal(options(number)["target"], train[k])


def test_the_start_covariance_keeps_the_targets_variance():
    S = start_cov(13, 0.1, 1e-4)
    np.testing.assert_array_equal(np.diag(S)[:10], 0.1)
    np.testing.assert_array_equal(np.diag(S)[10:], 1e-4)
    assert start_cov(13, 0.1, 0.0)[12, 12] > 0


def test_a_tiny_run_tests_its_policy_on_the_held_out_targets(tmp_path):
    """Two episodes on two training targets (random, then learned), then the test on three
    held-out targets: every test target has its steps (or None) in the summary, the
    training agent sums two starts, its GPs read the arm alone."""
    out = str(tmp_path / "run")
    s = REACHER_MULTI.parse([
        "--episodes", "2", "--training-targets", "2", "--test-targets", "3",
        "--horizon", "6", "--planning-horizon", "4", "--basis-functions", "3",
        "--policy-iters", "2", "--model-iters", "5", "--quiet", "--no-render",
        "--output", out])
    exp = REACHER_MULTI.experiment(s)
    summary = REACHER_MULTI.run(exp, s)
    paths = REACHER_MULTI.figures(exp, s)
    exp.close()
    assert len(summary["episodes"]) == 2 and summary["complete"]
    assert len(summary["test_steps"]) == 3 and summary["test_reached"] in range(4)
    assert summary["success"] == (summary["test_reached"] >= 3)
    agent = exp.agent
    assert agent.num_tasks == 2 and agent.m_init.shape == (2, 13)
    np.testing.assert_array_equal(agent.m_init[:, list(CONTEXT)], summary["training_targets"])
    assert agent.mgpr.X.shape[1] == 10 + 7  # the arm's state and the action, no target
    # the episodes ran on the training targets in turn
    with np.load(os.path.join(out, "data.npz")) as data:
        for k in (1, 2):
            np.testing.assert_array_equal(data[f"states_{k}"][0, 10:],
                                          summary["training_targets"][k - 1])
    assert any(p.endswith("targets.png") for p in paths)
    with open(os.path.join(out, "summary.json"), encoding="utf-8") as f:
        assert json.load(f)["test_steps"] == summary["test_steps"]
    # the diagnosis of the learned episode: predicted from the start of its own target,
    # the run's policy rerun on the episode's target (the same distances), the context
    # dimensions out of the one-step coverage
    from pilco.diagnose import diagnose, open_run

    result = diagnose(open_run(out), restarts=0)
    assert result["verdict"]
    one_step = result["model"]["one_step"]
    assert all(np.isfinite(one_step["rms_z_per_dim"]))
    np.testing.assert_array_equal(np.asarray(one_step["coverage_per_dim"])[list(CONTEXT)], 1.0)
    assert result["reconstruction"]["rerun_distance_error"] == pytest.approx(0.0, abs=1e-9)
