"""Safe PILCO's loop (:mod:`pilco.experiment.safety`): a policy predicted above the risk
threshold is never run on the system, ``mu`` moves as the rule says, every episode records
its predicted risk, whether it ran and whether it broke the constraint; and the two cars
(``pilco run cars``) run through it."""
from __future__ import annotations

import json

import numpy as np
import pytest

from pilco.constraints import HalfSpace, ViolationPenalty
from pilco.experiment import Experiment, RunHooks
from pilco.experiment.safety import SafeRun, Safety

from test_experiment import LineEnv, config

SAFE_ACTION = -0.25


def line_agent(wall):
    """A real PILCO agent on the line whose reward holds the penalty of ``wall``."""
    def build(data, start_states):
        from pilco.controllers import LinearController
        from pilco.models import PILCO
        from pilco.rewards import CombinedRewards, ExponentialReward

        reward = CombinedRewards(1, [ExponentialReward(1, W=[[4.0]], t=[[1.0]]),
                                     ViolationPenalty(wall, 1.0)])
        return PILCO(data, LinearController(1, 1, max_action=0.5, seed=0), reward,
                     horizon=4, m_init=[[0.0]], S_init=[[1e-3]])

    return build


class SafeLine(SafeRun):
    """Safe PILCO's loop on the line with ``wall`` as its constraint."""

    def __init__(self, wall, attempts=2, first_search="penalised"):
        self.build = line_agent(wall)
        self.safety = Safety(wall, 0.1, [SAFE_ACTION], attempts=attempts,
                             first_search=first_search)

    def make_env(self, run):
        return LineEnv()

    def build_agent(self, data, start_states):
        return self.build(data, start_states)


def run_line(tmp_path, wall, episodes=3, attempts=2, first_search="penalised"):
    cfg = config(episodes=episodes, random_episodes=1, horizon=5, model_iters=10,
                 policy_iters=3, random_action_scale=0.3)
    exp = Experiment(cfg, str(tmp_path / "run"), SafeLine(wall, attempts, first_search))
    return exp, exp.run()


def test_a_plain_first_search_weighs_the_risk_only_after_an_unsafe_policy(tmp_path,
                                                                          monkeypatch):
    """``first_search="plain"``: the loop's own search of each learned episode runs with
    the penalty's weight at 0 and the searches after an unsafe policy with mu (x1.5 each),
    continuing from the plain search's policy, then, none safe, one more from the policy
    the episode started from at the episode's first mu; mu is back in the reward after
    the episode as the unsafe searches left it. Planted: no policy can be safe."""
    from pilco.models import PILCO

    seen, starts = [], []
    search = PILCO.optimize_policy

    def watched(self, *args, **kwargs):
        seen.append(float(self.reward.base_rewards[1].weight.numpy()))
        starts.append(self.controller.W.numpy().copy())
        return search(self, *args, **kwargs)

    monkeypatch.setattr(PILCO, "optimize_policy", watched)
    wall = HalfSpace(1, [1.0], -5.0)
    exp, summary = run_line(tmp_path, wall, episodes=3, attempts=2, first_search="plain")
    # mu (1 at first) is raised after each unsafe search, the episode's last one included
    assert seen == pytest.approx([0.0, 1.5, 1.0, 0.0, 1.5 ** 3, 1.5 ** 2])
    # the repair continues from where the plain search ended; the last one starts where
    # the episode did
    assert not np.array_equal(starts[1], starts[0])
    assert np.array_equal(starts[2], starts[0]) and np.array_equal(starts[5], starts[3])
    learned = [r for r in summary["episodes"] if not r["random"]]
    assert [t["weight"] for r in learned for t in r["safety"]["tries"]] == pytest.approx(
        [0.0, 1.5, 1.0, 0.0, 1.5 ** 3, 1.5 ** 2])
    assert all(r["safety"]["tries"][-1]["from_start"] for r in learned)
    assert float(exp.agent.reward.base_rewards[1].weight.numpy()) == pytest.approx(1.5 ** 4)
    assert not any(r["safety"]["executed"] for r in learned)
    with pytest.raises(ValueError, match="first_search"):
        Safety(wall, 0.1, [SAFE_ACTION], first_search="later")


def test_a_policy_predicted_unsafe_is_never_executed(tmp_path):
    """Planted: every state from the start on breaks ``x <= -5`` (the start is at 0), so
    no policy can be safe: no learned episode runs its policy, each runs the safe action
    at every step and says so, and each raises mu by 1.5 per search."""
    wall = HalfSpace(1, [1.0], -5.0)
    exp, summary = run_line(tmp_path, wall, episodes=3, attempts=2)
    learned = [r for r in summary["episodes"] if not r["random"]]
    assert len(learned) == 2
    for record, episode in zip(learned, exp.episodes[1:]):
        safety = record["safety"]
        assert safety["executed"] is False and safety["risk"] > 0.99
        assert [t["weight"] for t in safety["tries"]] == pytest.approx(
            [safety["tries"][0]["weight"], 1.5 * safety["tries"][0]["weight"]])
        np.testing.assert_array_equal(episode.actions, SAFE_ACTION)  # never the policy
        assert record["violated"] and record["violation_steps"] == episode.steps + 1
    assert learned[1]["safety"]["tries"][0]["weight"] == pytest.approx(1.5 ** 2)
    counts = summary["safety"]
    assert (counts["learned"], counts["executed"], counts["executed_violated"]) == (2, 0, 0)
    # the records are saved as they are summarised
    saved = json.load(open(exp.store.summary_path))
    assert saved["safety"] == counts and saved["episodes"][1]["safety"]["executed"] is False


def test_a_policy_predicted_safe_runs_and_mu_is_lowered(tmp_path):
    """``x <= 100`` is never near: the policy's risk is ~0, so it runs (its actions are
    the policy's, not the safe action) and mu is lowered by 0.75 after each search."""
    wall = HalfSpace(1, [1.0], 100.0)
    exp, summary = run_line(tmp_path, wall, episodes=3)
    learned = [r for r in summary["episodes"] if not r["random"]]
    for k, record in enumerate(learned):
        assert record["safety"]["executed"] is True and record["safety"]["risk"] < 1e-6
        assert len(record["safety"]["tries"]) == 1  # the loop's own search sufficed
        assert record["safety"]["weight"] == pytest.approx(0.75 ** (k + 1))
        assert not record["violated"]
        # the risk recorded before the episode is the one the loop checked
        assert record["predicted_risk"]["independent"] == pytest.approx(
            record["safety"]["risk"], abs=1e-12)
    assert not np.all(exp.episodes[-1].actions == SAFE_ACTION)
    assert summary["safety"]["executed"] == 2


def test_the_safety_settings_are_checked():
    wall = HalfSpace(1, [1.0], 0.0)
    for bad, match in (({"threshold": 1.0}, "threshold"), ({"threshold": 0.0}, "threshold"),
                       ({"rule": "max"}, "rule"), ({"attempts": 0}, "attempts"),
                       ({"safe_action": [np.nan]}, "safe_action")):
        kw = {"constraint": wall, "threshold": 0.1, "safe_action": [0.0], **bad}
        with pytest.raises(ValueError, match=match):
            Safety(**kw)
    assert issubclass(SafeRun, RunHooks)


def test_the_two_cars_run_safe_pilco(tmp_path):
    """A short cars run (2 random episodes, 2 learned with tiny searches): the learned
    episodes record their risk and whether they ran, a run that ran none brakes, and
    the summary counts them; bad settings are usage errors."""
    from pilco.tasks.cars import CARS

    out = str(tmp_path / "cars")
    s = CARS.parse(["--output", out, "--episodes", "4", "--random-episodes", "2",
                    "--policy-iters", "2", "--policy-restarts", "1", "--model-iters", "10",
                    "--basis-functions", "5", "--quiet", "--no-figures", "--seed", "1"])
    exp = CARS.experiment(s)
    summary = CARS.run(exp, s)
    exp.close()
    learned = [r for r in summary["episodes"] if not r["random"]]
    assert len(learned) == 2
    for record, episode in zip(learned, exp.episodes[2:]):
        assert 0.0 <= record["safety"]["risk"] <= 1.0
        if not record["safety"]["executed"]:
            np.testing.assert_array_equal(episode.actions, s.safe_action)
            assert not record["violated"]  # braking from the start never reaches it
    counts = summary["safety"]
    assert counts["learned"] == 2 and counts["executed"] == sum(
        r["safety"]["executed"] for r in learned)
    for flags in (["--risk-threshold", "1.5"], ["--safe-action", "-0.3"]):
        with pytest.raises(SystemExit):
            CARS.parse(["--output", out + "-x", *flags])
    check_risk_against_samples(exp.agent)


def check_risk_against_samples(agent):
    """The moment-matched risk of a learned agent against trajectories sampled through its
    GP dynamics (:func:`pilco.models.safe.sampled_risk`), for a wall ``x1 <= b`` placed k
    predicted standard deviations beyond the predicted final position: far beyond it
    neither says the car gets there, far before it both say it does, and in between they
    agree within 0.2 (moment matching is an approximation: the sampled distribution is
    not Gaussian, and the sampled risk may exceed even the union bound)."""
    from pilco.models.safe import predicted_risk, sampled_risk

    M, S = agent.predict_trajectory()
    end, std = M[-1, 0], float(np.sqrt(S[-1, 0, 0]))
    for k, low, high in ((-6.0, 0.95, 1.0), (0.5, 0.0, 1.0), (6.0, 0.0, 0.05)):
        wall = HalfSpace(4, [1.0, 0.0, 0.0, 0.0], end + k * std)
        sampled, se = sampled_risk(agent, wall, samples=300, seed=1)
        predicted = predicted_risk(agent, wall, "independent")
        assert low <= predicted <= high and low - 3 * se <= sampled <= high + 3 * se, (
            k, predicted, sampled)
        assert abs(sampled - predicted) <= 0.2, (k, predicted, sampled)
        assert predicted_risk(agent, wall, "union") >= predicted - 1e-12


def test_the_cars_example_runs_as_a_script(tmp_path):
    """``examples/cars.py`` with tiny settings: exit 0, the safety counts printed and the
    summary written."""
    import os
    import subprocess
    import sys

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    out = tmp_path / "run"
    proc = subprocess.run(
        [sys.executable, os.path.join(root, "examples", "cars.py"), "--output", str(out),
         "--episodes", "3", "--random-episodes", "2", "--policy-iters", "1",
         "--policy-restarts", "1", "--model-iters", "5", "--basis-functions", "3",
         "--quiet", "--no-figures"], capture_output=True, text=True, timeout=600, cwd=root,
        env=dict(os.environ, PYTHONPATH=root))  # this checkout's pilco
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "learned episodes 1, executed" in proc.stdout
    summary = json.load(open(out / "summary.json"))
    assert summary["task"] == "cars" and summary["safety"]["learned"] == 1


def test_the_cart_pole_on_a_finite_track(tmp_path):
    """``--track-bound B`` records every episode's crossing of ``|x| <= B`` (without the
    loop every learned policy runs); ``--safe`` adds Safe PILCO's loop (the learned
    episodes record their risk; one that did not run applied the brake); ``--safe``
    without a track is a usage error; without a track nothing is recorded."""
    from pilco.tasks.cartpole import CARTPOLE, CartBrake

    tiny = ["--episodes", "3", "--horizon", "8", "--basis-functions", "3", "--policy-iters",
            "2", "--model-iters", "10", "--policy-restarts", "1", "--quiet", "--no-figures",
            "--no-render", "--seed", "1"]
    for flags, safe in ((["--track-bound", "0.05"], False),
                        (["--track-bound", "0.05", "--safe"], True)):
        out = str(tmp_path / f"safe-{safe}")
        s = CARTPOLE.parse(["--output", out, *tiny, *flags])
        exp = CARTPOLE.experiment(s)
        summary = CARTPOLE.run(exp, s)
        exp.close()
        for record, episode in zip(summary["episodes"], exp.episodes):
            assert record["violated"] == bool(np.any(np.abs(episode.states[:, 0]) > 0.05))
        learned = [r for r in summary["episodes"] if not r["random"]]
        for record in learned:  # every learned policy's predicted risk, both rules
            risk = record["predicted_risk"]
            assert 0.0 <= risk["independent"] <= risk["union"] + 1e-12
            assert risk["union"] <= 1.0
        assert "predicted_risk" not in summary["episodes"][0]  # a random episode
        assert ("safety" in learned[0]) == safe
        counts = summary["safety"]
        assert counts["learned"] == 2
        if not safe:
            assert counts["executed"] == 2
        for record, episode in zip(summary["episodes"], exp.episodes):
            if safe and not record["random"] and not record["safety"]["executed"]:
                brake = CartBrake(max_force=s.max_force)
                np.testing.assert_array_equal(
                    episode.actions, np.vstack([brake(x) for x in episode.states[:-1]]))
    with pytest.raises(SystemExit):
        CARTPOLE.parse(["--output", str(tmp_path / "x"), "--safe"])
    plain = CARTPOLE.parse(["--output", str(tmp_path / "plain")])
    assert plain.track_bound is None and not plain.safe


def test_the_cart_brake_keeps_the_cart_on_the_track_where_no_force_does_not():
    """The cart-pole's safe action, run on the real cart-pole for a whole episode (40
    steps of 0.1 s) from 60 draws of the start distribution: the cart never leaves a
    0.5 m track; with no force it rolls off from some of the same starts (the start's
    speed and the pole's swinging carry it)."""
    import gymnasium

    from pilco.envs import CARTPOLE_ID
    from pilco.tasks.cartpole import CartBrake

    def farthest(policy, seed):
        env = gymnasium.make(CARTPOLE_ID, start_std=0.1, noise_std=0.01,
                             max_episode_steps=40)
        x, _ = env.reset(seed=seed)
        reach = abs(env.unwrapped.state[0])
        for _ in range(40):
            x, *_ = env.step(policy(x))
            reach = max(reach, abs(env.unwrapped.state[0]))
        env.close()
        return reach

    brake = CartBrake()
    braked = [farthest(brake, seed) for seed in range(60)]
    rolling = [farthest(lambda x: np.zeros(1), seed) for seed in range(60)]
    assert max(braked) < 0.5
    assert sum(r > 0.5 for r in rolling) >= 3
    assert np.all(np.abs([brake(np.array([x, v, 0.0, 0.0]))
                          for x in (-5, 5) for v in (-5, 5)]) <= 10.0)


def test_a_safe_action_may_be_a_controller_of_the_state():
    """``Safety.safe_action`` is a constant or a controller ``x -> u``; a controller that
    returns a non-finite action is an error that names it."""
    wall = HalfSpace(1, [1.0], 0.0)
    constant = Safety(wall, 0.1, [SAFE_ACTION])
    np.testing.assert_array_equal(constant.action_at(np.array([3.0])), [SAFE_ACTION])
    follow = Safety(wall, 0.1, lambda x: -0.5 * x)
    np.testing.assert_array_equal(follow.action_at(np.array([2.0])), [-1.0])
    broken = Safety(wall, 0.1, lambda x: np.array([np.nan]))
    with pytest.raises(ValueError, match="safe action"):
        broken.action_at(np.array([0.0]))
