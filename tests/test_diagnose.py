"""The diagnosis of a failed episode (pilco.diagnose, python -m pilco.diagnose):
on a tiny real run (a point on a line, a real PILCO agent), the verdict rules on synthetic
numbers, and the distance a saturating cost measures."""
from __future__ import annotations

import copy
import dataclasses
import json
import math

import gymnasium
import numpy as np
import pytest

from pilco.controllers import RbfController
from pilco.experiment import Experiment, ExperimentConfig, FunctionHooks, saturating_cost
from pilco.diagnose import (VERDICTS, Thresholds, action_error, agent_of_episode, diagnose,
                            format_report, verdict, write_diagnosis)
from pilco.diagnose.checks import mean_dynamics
from pilco.diagnose.geometry import cost_geometry, distance_moments, slope_ratio
from pilco.models import PILCO
from pilco.rewards import AxisBumpsReward, CartPoleReward, CombinedRewards, ExponentialReward

WIDTH = 0.5  # cost width of the line task [m]
STEPS = 6


class Line(gymnasium.Env):
    """A point on a line from x = 0: ``x' = x + u`` (|u| <= 0.5); distance ``|x - 1|``."""

    def __init__(self):
        self.observation_space = gymnasium.spaces.Box(-10, 10, (1,), np.float64)
        self.action_space = gymnasium.spaces.Box(-0.5, 0.5, (1,), np.float64)
        self.x = np.zeros(1)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.x = np.zeros(1)
        return self.x.copy(), {"distance": 1.0}

    def step(self, action):
        self.x = self.x + np.clip(action, -0.5, 0.5)
        d = float(abs(self.x[0] - 1.0))
        return self.x.copy(), -d, d < 0.05, False, {"distance": d}


def build(data, start_states):
    controller = RbfController(1, 1, num_basis_functions=3, max_action=0.5, seed=1)
    reward = ExponentialReward(1, W=[[1.0 / WIDTH ** 2]], t=[[1.0]])
    return PILCO(data, controller, reward, horizon=STEPS, m_init=start_states[0:1],
                 S_init=1e-4 * np.eye(1))


def config():
    return ExperimentConfig(task="line", env_id="unused", seed=2, episodes=3,
                            random_episodes=1, horizon=STEPS, random_action_scale=0.3,
                            model_iters=20, policy_iters=4, cost_width=WIDTH,
                            predictions=False, quiet=True, render=False)


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    """A finished 3-episode run (1 random, 2 learned), reopened as a user would."""
    directory = str(tmp_path_factory.mktemp("diagnose") / "run")
    exp = Experiment(config(), directory, FunctionHooks(build, Line))
    exp.run()
    return directory


def reopen(directory):
    return Experiment.resume(directory, config(), FunctionHooks(build, Line))


def test_diagnose_a_run_directory_writes_every_field(run_dir):
    exp = reopen(run_dir)
    result = diagnose(exp, restarts=1)
    path = write_diagnosis(result, f"{run_dir}/diagnosis.json")
    with open(path, encoding="utf-8") as f:
        saved = json.load(f)
    assert saved["episode"] == 3 and saved["verdict"] == result["verdict"]
    for key in ("reconstruction", "model", "optimiser", "objective", "facts", "notes"):
        assert key in saved
    # the saved agent with its data cut back is the agent that ran episode 3
    assert saved["reconstruction"]["source"] == "agent.npz"
    assert saved["reconstruction"]["action_error"] <= 1e-9
    assert saved["reconstruction"]["rerun_distance_error"] <= 1e-12
    ep = exp.episodes[2]
    one, multi = saved["model"]["one_step"], saved["model"]["multi_step"]
    assert 0.0 <= one["coverage"] <= 1.0 and len(one["coverage_per_dim"]) == 1
    assert len(multi["pred_distance_mean"]) == STEPS + 1
    assert multi["pred_distance_mean"][0] == pytest.approx(1.0, abs=0.02)
    # the cost's distance is the env's: the real cost is the saturating cost of its distances
    np.testing.assert_allclose(multi["real_cost"], saturating_cost(ep.distances, WIDTH),
                               atol=1e-12)
    assert saved["objective"]["start_widths"] == pytest.approx(2.0, abs=1e-9)
    # the open loop applies the episode's actions to the model's mean from the real start
    loop = saved["model"]["open_loop"]
    assert loop["error"][0] == 0.0 and len(loop["error"]) == ep.steps + 1
    # the run's predicted cost is its policy objective on the episode's model
    agent = PILCO.load(f"{run_dir}/agent.npz")
    X, Y = exp.training_data()
    before = exp.episodes[0].steps + exp.episodes[1].steps
    agent.set_data((X[:before], Y[:before]))
    opt = saved["optimiser"]
    assert opt["run_pred_cost"] == pytest.approx(STEPS - agent.expected_return(), rel=1e-9)
    X3, _ = ep.transitions()
    mean, _ = agent.one_step_prediction(X3)
    step = mean_dynamics(agent)
    np.testing.assert_allclose([step(x[:1], x[1:]) for x in X3], X3[:, :1] + mean, rtol=1e-7)
    assert loop["distance"][1] == pytest.approx(abs(X3[0, 0] + mean[0, 0] - 1.0), rel=1e-7)
    assert [c["start"] for c in opt["candidates"]] == ["run", "continued", "random"]
    # continuing from the run's policy keeps the best policy evaluated: never worse
    assert opt["candidates"][1]["pred_cost"] <= opt["run_pred_cost"] + 1e-9
    assert saved["verdict"]["label"] in VERDICTS
    assert verdict(result["facts"]) == result["verdict"]
    assert "Verdict:" in format_report(result)
    # the policy from other starts: how many meet the rule, and the two objectives
    starts = saved["starts"]
    assert starts["starts"] == 20 and 0 <= starts["solved"] <= 20
    assert starts["solved_fraction"] == pytest.approx(starts["solved"] / 20)
    assert starts["plain_return"] == pytest.approx(agent.expected_return(), rel=1e-9)
    agent.start_spread = starts["spread"]
    assert starts["mixture_return"] == pytest.approx(agent.expected_return(), rel=1e-9)
    assert "other start states" in format_report(result)


def test_the_start_check_compares_the_plain_objective_with_the_mixture(run_dir):
    """Whatever start points or wide start the run's search had (the cart-pole's once
    solved), the check's plain return is the one Gaussian's, and they are left in place."""
    from pilco.diagnose.checks import start_check

    exp = reopen(run_dir)
    agent = exp.agent
    plain = agent.expected_return()
    agent.start_spread = 0.5
    mixed = agent.expected_return()
    agent.start_spread = None
    agent.start_scale = 2.0
    agent.start_points = agent.m_init + 0.3
    assert agent.expected_return() != pytest.approx(plain, rel=1e-6)
    out = start_check(exp, 3, None, 0, spread=0.5)
    assert out["plain_return"] == pytest.approx(plain, rel=1e-12)
    assert out["mixture_return"] == pytest.approx(mixed, rel=1e-12)
    assert agent.start_scale == 2.0 and agent.start_points is not None


def test_each_optimiser_candidate_is_one_search_from_its_own_start(run_dir):
    """With restarts in the run's settings, a candidate of the optimiser check is still one
    search from its start: the run's restarts would draw the same further policies for
    every candidate, and the best of those would stand for each of them."""
    from pilco.diagnose.checks import optimiser_check

    exp = reopen(run_dir)
    exp.config = dataclasses.replace(exp.config, policy_restarts=3, policy_restart_from=1)
    assert exp.config.policy_restarts_at(3, False) == 3
    drawn = []

    def randomizer(controller, seed):
        drawn.append(seed)
        rng = np.random.default_rng(seed)
        controller.centers.assign(rng.standard_normal(controller.centers.shape))
        controller.targets.assign(0.1 * rng.standard_normal(controller.targets.shape))

    exp.agent.controller.randomizer = randomizer
    geometry = cost_geometry(exp.agent.reward)
    out = optimiser_check(exp, 3, geometry, restarts=2, seed=0, env=None,
                          thresholds=Thresholds())
    assert [c["start"] for c in out["candidates"]] == ["run", "continued", "random", "random"]
    # two random candidates: two draws, one per candidate, each its candidate's seed
    assert drawn == [c["seed"] for c in out["candidates"][2:]]
    assert len(set(drawn)) == 2


def test_the_report_shows_what_happens_between_its_rows(run_dir):
    """A distance with a period of the rows' spacing (a pole spinning through the top
    every 5 steps) reads as steady at the rows; the ranges between the rows show it."""
    result = copy.deepcopy(diagnose(reopen(run_dir), restarts=0))
    multi = result["model"]["multi_step"]
    spin = np.where(np.arange(41) % 5 == 0, 0.07, 0.95)
    spin[0] = 1.0
    for key in ("pred_distance_mean", "real_distance"):
        multi[key] = spin.copy()
    multi["pred_distance_std"] = np.full(41, 0.02)
    multi["pred_cost"] = multi["real_cost"] = saturating_cost(spin, WIDTH)
    result["model"]["open_loop"]["distance"] = spin.copy()
    report = format_report(result, every=5)
    rows = [line.split() for line in report.splitlines()
            if line.strip().split(" ")[0] in {"10", "15", "20"}]
    assert len(rows) == 3
    for row in rows:
        assert row[1] == "0.070" and row[3] == "0.070"  # the rows alone: near the top
        assert row[5] == "0.070-0.950" and row[6] == "0.070-0.950"  # between: the spin
        # the block's summed cost: four steps far from the top, one near it
        assert float(row[7]) == pytest.approx(float(np.sum(saturating_cost(spin[6:11],
                                                                           WIDTH))), abs=1e-3)


def test_an_earlier_episode_is_replayed_with_the_runs_settings(run_dir):
    exp = reopen(run_dir)
    view, info = agent_of_episode(exp, 2)
    assert info["source"] == "replay" and len(view.episodes) == 1
    # the replayed policy is the one that ran episode 2: it repeats its actions
    assert info["action_error"] <= 1e-9
    assert action_error(view.agent, exp.episodes[2]) > 1e-6  # and is not episode 3's
    with pytest.raises(ValueError, match="not a learned episode"):
        agent_of_episode(exp, 1)


@pytest.mark.parametrize("episode, message", [
    ("1", "episode 1 is not a learned episode (learned episodes: 2, 3)"),
    ("7", "episode 7 is not a learned episode (learned episodes: 2, 3)"),
])
def test_the_command_line_refuses_an_episode_the_run_did_not_learn(run_dir, episode,
                                                                   message, capsys):
    """A usage error in one line (status 2), before any diagnosis."""
    from pilco.diagnose import main

    assert main([run_dir, "--episode", episode, "--log-level", "WARNING"]) == 2
    captured = capsys.readouterr()
    assert captured.err == f"pilco diagnose: error: {run_dir}: {message}\n"
    assert captured.out == ""


def test_the_command_line_prints_the_report_and_writes_the_json(run_dir, tmp_path, capsys):
    from pilco.diagnose import main

    out = tmp_path / "d.json"
    # a run of no known task is reopened through its saved agent (enough for the last
    # episode); its env id is not registered, so the candidates are not rolled out
    assert main([run_dir, "--restarts", "0", "--output", str(out),
                 "--log-level", "WARNING"]) == 0
    printed = capsys.readouterr().out
    saved = json.loads(out.read_text())
    assert saved["episode"] == 3 and saved["reconstruction"]["source"] == "agent.npz"
    assert [c["start"] for c in saved["optimiser"]["candidates"]] == ["run", "continued"]
    assert "real_solved" not in saved["optimiser"]["candidates"][0]
    assert f"Verdict: {saved['verdict']['label']}" in printed and str(out) in printed


FAILED = dict(solved=False, start_widths=1.9, pred_solved=False, coverage=0.97,
              worst_dim_coverage=0.9, open_loop_wrong=False, final_inside=True, optimism=0.5,
              episode_pred_cost=20.0, run_cost=20.0, gain=0.5, better_solves_real=None)


def rule(**changes):
    v = verdict({**FAILED, **changes})
    return v["label"], v["rule"]


def test_verdict_rules_in_order_on_synthetic_numbers():
    assert rule(solved=True, coverage=0.1, gain=50.0) == ("solved", 1)
    assert rule(start_widths=3.01) == ("objective: cost flat", 2)
    # a flat start that a clearly better policy of the same objective overcame on the
    # real system is the optimiser's failure, not the objective's
    assert rule(start_widths=4.0, gain=9.0, better_solves_real=True) == ("optimiser", 4)
    assert rule(start_widths=4.0, gain=9.0, better_solves_real=False) == (
        "objective: cost flat", 2)
    assert rule(start_widths=4.0, gain=0.5, better_solves_real=True) == (
        "objective: cost flat", 2)
    assert rule(start_widths=2.99) != ("objective: cost flat", 2)
    # only while the search stays on the plateau (at least 90 % of the largest cost): a
    # policy predicted well below it left the flat start behind, and the later rules judge
    assert rule(start_widths=4.0, max_cost=40.0, run_cost=36.0) == ("objective: cost flat", 2)
    assert rule(start_widths=4.0, max_cost=40.0, run_cost=35.9) == (
        "objective: optimum short of the target", 7)
    assert rule(start_widths=4.0, max_cost=40.0, run_cost=14.2, pred_solved=True,
                open_loop_wrong=True) == ("model", 3)
    # predicted to solve but failed: one-step coverage (overall 0.90, worst dimension 0.70)
    # decides, before any better optimum
    assert rule(pred_solved=True, coverage=0.89, gain=50.0) == ("model", 3)
    assert rule(pred_solved=True, worst_dim_coverage=0.69) == ("model", 3)
    # ... or the model's open loop misses the real closest approach by the success distance
    assert rule(pred_solved=True, open_loop_wrong=True) == ("model", 3)
    assert rule(pred_solved=True, coverage=0.90, worst_dim_coverage=0.70,
                gain=50.0, better_solves_real=True) == ("objective", 3)
    # a clearly better policy that solves on the real system outweighs the model's error
    assert rule(gain=2.0, better_solves_real=True, optimism=30.0) == ("optimiser", 4)
    # the model's error about the run's policy (real minus predicted cost) beyond the clear
    # margin and beyond the re-optimisation gain
    assert rule(gain=3.0, better_solves_real=False, optimism=3.01) == ("objective", 5)
    assert rule(optimism=2.0, worst_dim_coverage=0.5) == ("model", 5)
    assert rule(optimism=1.99) != ("objective", 5)  # within max(1, 10 % of 20)
    assert rule(gain=3.0, better_solves_real=False, optimism=3.0) == ("optimiser", 6)
    # clearly better: max(1, 10 % of the run's predicted cost)
    assert rule(gain=2.0) == ("optimiser", 6)
    assert rule(gain=1.99) != ("optimiser", 6)
    assert rule(run_cost=5.0, gain=1.0) == ("optimiser", 6)
    assert rule(run_cost=5.0, gain=0.99) != ("optimiser", 6)
    assert "caveat" in verdict({**FAILED, "gain": 3.0, "better_solves_real": False})
    assert "caveat" not in verdict({**FAILED, "gain": 3.0})
    # the model predicts the failure and nothing better was found
    assert rule(coverage=0.5) == ("model", 7)
    assert rule(worst_dim_coverage=0.69) == ("model", 7)
    assert rule(open_loop_wrong=True) == ("model", 7)
    assert rule(final_inside=False) == ("model", 7)
    assert rule() == ("objective: optimum short of the target", 7)
    # without a known cost geometry the distance- and cost-based rules are skipped
    assert rule(start_widths=None, pred_solved=None, final_inside=None, optimism=None,
                episode_pred_cost=None, open_loop_wrong=None) == (
        "objective: optimum short of the target", 7)
    strict = Thresholds(coverage=0.99)
    assert verdict(FAILED, strict)["label"] == "model"


def test_the_cost_slope_and_the_distance_a_cost_measures():
    assert slope_ratio(1.0) == pytest.approx(1.0)
    assert slope_ratio(3.0) == pytest.approx(3 * math.exp(-4))
    assert slope_ratio(Thresholds().flat_widths) < 0.06
    D, sigma, target = 5, 0.2, np.array([1.2, 0.4, 0.4])
    W = np.zeros((D, D))
    W[:3, :3] = np.eye(3) / sigma ** 2
    t = np.zeros((1, D))
    t[0, :3] = target
    geometry = cost_geometry(ExponentialReward(D, W, t))
    assert geometry.width == pytest.approx(sigma) and geometry.dims == (0, 1, 2)
    X = np.random.default_rng(0).normal(size=(4, D))
    np.testing.assert_allclose(geometry.distance(X), np.linalg.norm(X[:, :3] - target, axis=1))
    combined = cost_geometry(CombinedRewards(D, [ExponentialReward(D, W, t),
                                                 ExponentialReward(D, 16 * W, t)]))
    assert combined.width == pytest.approx(sigma) and combined.max_reward == 2.0
    # a subtracted penalty (the reacher's joint-limit bumps) is not part of the geometry
    penalised = cost_geometry(CombinedRewards(D, [ExponentialReward(D, W, t),
                                                  AxisBumpsReward(D, [3, 3], [-1, 1], [.1, .1])],
                                              [1.0, -0.5]))
    assert penalised.width == pytest.approx(sigma) and penalised.max_reward == 1.0
    assert penalised.dims == (0, 1, 2)
    tip = cost_geometry(CartPoleReward(pendulum_length=0.5, width=0.25))
    states = np.array([[0.0, 0, 0, np.pi], [0.0, 0, 0, 0.0], [0.3, 0, 0, np.pi]])
    np.testing.assert_allclose(tip.distance(states), [0.0, 1.0, 0.3], atol=1e-12)
    # no spread: the sampled distance is the distance itself
    mean, std = distance_moments(geometry, X[:2], np.zeros((2, D, D)))
    np.testing.assert_allclose(mean, geometry.distance(X[:2]))
    np.testing.assert_allclose(std, 0.0, atol=1e-12)
