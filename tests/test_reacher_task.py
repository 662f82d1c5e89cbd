"""The reacher task's own pieces: the joint-limit cost and the checks of its flags."""
from __future__ import annotations

import os

import numpy as np
import pytest

from pilco.rewards import CombinedRewards, ExponentialReward
from pilco.tasks import reacher, reacher_agent
from pilco.tasks.adaptation import ADAPTATION
from pilco.tasks.reacher import DAMAGED_REACHER, REACHER
from pilco.tasks.settings import settings_to_dict

# the Fetch arm's limits (pilco/envs/fetch_model.py); rolls are unlimited
LIMITS = np.array([[-1.6056, 1.6056], [-1.221, 1.518], [-np.inf, np.inf], [-2.251, 2.251],
                   [-np.inf, np.inf], [-2.16, 2.16], [-np.inf, np.inf]])


def test_one_bump_per_finite_limit_on_its_joint():
    bumps = reacher_agent.limit_bumps(10, LIMITS, 0.1)
    centres = sorted(zip(bumps.dims, bumps.t.numpy()))
    expected = sorted((3 + j, v) for j in (0, 1, 3, 5) for v in LIMITS[j])
    assert [c[0] for c in centres] == [e[0] for e in expected]
    np.testing.assert_allclose([c[1] for c in centres], [e[1] for e in expected])
    # each looks at one joint angle only, with width 0.1 rad and weight 1
    np.testing.assert_allclose(bumps.widths.numpy(), 0.1)
    np.testing.assert_allclose(bumps.coefs.numpy(), 1.0)
    assert reacher_agent.limit_bumps(10, np.full((7, 2), np.inf) * [-1, 1], 0.1) is None


def test_the_bumps_lower_the_reward_near_a_limit_only():
    D = 10
    target = np.zeros((1, D))
    position = ExponentialReward(D, np.diag([1.0] * 3 + [0.0] * 7), target)
    bumps = reacher_agent.limit_bumps(D, LIMITS, 0.1)
    reward = CombinedRewards(D, [position, bumps], [1.0, -0.5])
    s = 1e-6 * np.eye(D)

    def value(q):
        m = np.zeros((1, D))
        m[0, 3:] = q
        return float(reward.compute_reward(m, s)[0].numpy().squeeze())

    mid = np.zeros(7)
    near = mid.copy()
    near[3] = 2.251 - 0.02  # elbow flex 2 cm-rad from its upper limit
    assert value(mid) == pytest.approx(1.0, abs=1e-5)  # position reward only
    assert value(near) == pytest.approx(1.0 - 0.5 * np.exp(-0.02 ** 2 / (2 * 0.01)), rel=1e-4)
    rolled = mid.copy()
    rolled[2] = 50.0  # unlimited joints carry no bump
    assert value(rolled) == pytest.approx(1.0, abs=1e-5)


@pytest.mark.parametrize("argv, message", [
    (["--cost-width", "-1"], "--cost-width: must be positive"),
    (["--cost-width", "inf"], "--cost-width: must be positive"),
    (["--cost-width", "wide"], "--cost-width: expected a number"),
    (["--fine-cost-width", "-0.1"], "--fine-cost-width: must be zero or positive"),
    (["--limit-cost", "nan"], "--limit-cost: must be zero or positive"),
    (["--start-var", "0"], "--start-var: must be positive"),
    (["--max-action", "-0.1"], "--max-action: must be positive"),
    (["--planning-horizon", "0"], "--planning-horizon: must be at least 1"),
    (["--planning-horizon", "2.5"], "--planning-horizon: expected an integer"),
])
def test_bad_flags_are_refused_by_name(argv, message, capsys, tmp_path):
    with pytest.raises(SystemExit) as exc:
        REACHER.parse([*argv, "--output", str(tmp_path)])
    assert exc.value.code == 2
    assert message in capsys.readouterr().err


def test_a_sweep_refuses_bad_task_values_before_ray(tmp_path):
    from pilco.sweep import cli

    args = cli.build_parser().parse_args(["damaged_reacher", "--seeds", "0-1",
                                          "--set", "cost_width=-0.4",
                                          "--output", str(tmp_path)])
    with pytest.raises(ValueError, match="--cost-width: must be positive"):
        cli.plan(args, [])


def test_good_flags_pass():
    args = REACHER.parse(["--limit-cost", "0.1", "--fine-cost-width", "0"])
    assert args.limit_cost == 0.1 and args.limit_cost_weight == 0.5


def tiny_agent(argv):
    """The reacher task's agent for ``argv``, built on 12 random transitions."""
    rng = np.random.default_rng(0)
    X, Y = rng.normal(size=(12, 17)), 0.01 * rng.normal(size=(12, 10))
    start = np.concatenate([[1.0, 0.5, 0.6], np.zeros(7)])[None, :]
    args = REACHER.parse([*argv, "--basis-functions", "3"])
    return reacher_agent.agent_builder(args, np.array([1.2, 0.38, 0.38]), LIMITS)((X, Y), start)


def test_the_default_agent_has_the_limit_bumps_and_the_paper_preset_not():
    def reward_terms(argv):
        r = tiny_agent(argv).reward
        return [type(t).__name__ for t in getattr(r, "base_rewards", [r])], r

    names, reward = reward_terms([])
    # the position cost (coarse + fine) and the bumps at the finite limits, subtracted
    assert names == ["CombinedRewards", "AxisBumpsReward"]
    assert len(reward.base_rewards[1].dims) == 8
    np.testing.assert_allclose(reward.coefs.numpy(), [1.0, -0.5])
    assert reward_terms(["--limit-cost", "0"])[0] == ["ExponentialReward"] * 2
    assert reward_terms(["--preset", "paper-code"])[0] == ["ExponentialReward"]


def test_the_policy_starts_near_the_start_state_with_policy_init_var():
    start = np.concatenate([[1.0, 0.5, 0.6], np.zeros(7)])
    near = tiny_agent(["--policy-init-var", "0.01"]).controller
    far = tiny_agent(["--policy-init-var", "0"]).controller
    # centres within a few std (0.1) of the start state; without the flag N(0, I)
    offsets = near.centers.numpy() - start
    assert near.centers.numpy().shape == (3, 10) and np.all(np.abs(offsets) < 0.5)
    assert np.all(np.abs(near.targets.numpy()) < 0.5)
    assert np.max(np.abs(far.centers.numpy() - start)) > 0.5
    # the same seed gives the same policy
    np.testing.assert_array_equal(
        near.centers.numpy(), tiny_agent(["--policy-init-var", "0.01"]).controller.centers.numpy())


def test_the_schedule_widens_the_main_cost_and_start_variance_early_only():
    argv = ["--early-cost-width", "1.0", "--early-start-var", "0.1", "--early-episodes", "2"]
    agent = tiny_agent(argv)
    args = REACHER.parse([*argv, "--basis-functions", "3"])
    hook = reacher_agent.schedule(args)
    main = reacher_agent.main_position_reward(agent.reward)
    fine = agent.reward.base_rewards[0].base_rewards[1]
    far = np.concatenate([[1.2 + 0.5, 0.38, 0.38], np.zeros(7)])[None, :]

    def main_reward_at_far():
        return float(main.moments(far, np.zeros((10, 10)))[0].numpy().squeeze())

    assert main_reward_at_far() == pytest.approx(np.exp(-0.5 * 0.5 ** 2 / 0.2 ** 2))
    for number, width, var in [(2, 1.0, 0.1), (3, 1.0, 0.1), (4, 0.2, 1e-4), (2, 1.0, 0.1)]:
        hook(agent, number)  # episode 1 is the random one
        assert main_reward_at_far() == pytest.approx(np.exp(-0.5 * 0.5 ** 2 / width ** 2))
        np.testing.assert_allclose(agent.S_init, var * np.eye(10))
        # the fine cost and the target stay
        np.testing.assert_allclose(np.diag(fine.W.numpy())[:3], 1 / 0.05 ** 2)
        np.testing.assert_allclose(main.t.numpy()[0, :3], [1.2, 0.38, 0.38])
    # without a schedule the hook changes nothing
    off = ["--early-start-var", "0"]
    plain = tiny_agent(off)
    before = plain.reward.base_rewards[0].base_rewards[0].W.numpy().copy(), plain.S_init
    reacher_agent.schedule(REACHER.parse(off))(plain, 2)
    np.testing.assert_array_equal(reacher_agent.main_position_reward(plain.reward).W.numpy(),
                                  before[0])
    np.testing.assert_array_equal(plain.S_init, before[1])


def test_the_reacher_arms_widen_their_first_learned_start_by_default():
    healthy = REACHER.parse([])
    assert (healthy.early_start_var, healthy.early_cost_width, healthy.early_episodes) == (
        0.1, 0.0, 1)
    assert healthy.policy_init_var == 0.1
    # the damaged arm (the elbow stuck in the healthy start pose) has the healthy defaults
    damaged = DAMAGED_REACHER.parse([])
    damaged_values = settings_to_dict(damaged)
    for key, value in settings_to_dict(healthy).items():
        if key != "output":
            assert damaged_values[key] == value, key
    assert damaged.damage_mode == "stuck"
    # so does the adaptation's healthy arm, with the reacher's budget of learned episodes
    adapted = settings_to_dict(ADAPTATION.parse([]))
    for key, value in settings_to_dict(healthy).items():
        if key not in ("output", "episodes"):
            assert adapted[key] == value, key
    assert adapted["healthy_episodes"] == healthy.episodes - healthy.random_episodes == 3
    for other in (REACHER.parse(["--preset", "paper-code"]),
                  DAMAGED_REACHER.parse(["--preset", "paper-code"])):
        assert (other.early_start_var, other.policy_init_var) == (0.0, 0.0)
    agent = tiny_agent([])
    hook = reacher_agent.schedule(healthy)
    hook(agent, 2)
    np.testing.assert_allclose(agent.S_init, 0.1 * np.eye(10))
    hook(agent, 3)
    np.testing.assert_allclose(agent.S_init, 1e-4 * np.eye(10))


def test_a_saved_run_resumes_with_its_settings_and_todays_defaults_for_missing_ones(
        tmp_path):
    import json

    new = settings_to_dict(REACHER.parse(["--output", str(tmp_path / "new"),
                                          "--cost-width", "0.3", "--seed", "4"]))
    old = {k: v for k, v in new.items()
           if k not in ("early_start_var", "limit_cost", "fine_cost_width", "policy_init_var")}
    run = tmp_path / "old"
    run.mkdir()
    (run / "progress.json").write_text(json.dumps({"settings": old}))
    resumed = REACHER.parse(["--resume", str(run)])
    assert (resumed.early_start_var, resumed.limit_cost, resumed.fine_cost_width,
            resumed.policy_init_var) == (0.1, 0.1, 0.05, 0.1)
    assert (resumed.cost_width, resumed.seed) == (0.3, 4)
    assert ADAPTATION.parse(["--resume", str(run)]).early_start_var == 0.1
    # a saved value wins, and so does a flag given again
    (run / "progress.json").write_text(json.dumps({"settings": dict(new,
                                                                    early_start_var=0.05)}))
    assert REACHER.parse(["--resume", str(run)]).early_start_var == 0.05
    assert REACHER.parse(["--resume", str(run), "--early-start-var", "0.2"]
                              ).early_start_var == 0.2


def test_the_adaptation_has_the_reachers_costs(tmp_path):
    import json

    args = ADAPTATION.parse(["--output", str(tmp_path / "new")])
    assert args.fine_cost_width == 0.05 and args.limit_cost == 0.1
    agent = reacher_agent.agent_builder(args, np.array([1.2, 0.38, 0.38]), LIMITS)(
        (np.zeros((3, 17)), np.zeros((3, 10))), np.zeros((1, 10)))
    healthy = reacher_agent.agent_builder(REACHER.parse([]), np.array([1.2, 0.38, 0.38]),
                                          LIMITS)((np.zeros((3, 17)), np.zeros((3, 10))),
                                                  np.zeros((1, 10)))
    assert agent.expected_return() == healthy.expected_return()
    np.testing.assert_allclose(agent.reward.base_rewards[0].base_rewards[1].W.numpy(),
                               reacher_agent.position_weights(10, 0.05))  # the fine cost
    assert ADAPTATION.parse(["--limit-cost", "0"]).limit_cost == 0.0
    # a run saved while the adaptation had no fine cost (null) resumes without it (0: none)
    run = tmp_path / "old"
    run.mkdir()
    (run / "progress.json").write_text(json.dumps({"settings": dict(settings_to_dict(args),
                                                                    fine_cost_width=None)}))
    assert ADAPTATION.parse(["--resume", str(run)]).fine_cost_width == 0.0


class _HealthyRun:
    """The part of an Experiment that the adaptation's schedule reads while the arm is
    healthy; learned episode k (1-based) reaches the target when k is in ``reaching``."""

    def __init__(self, reaching, done=0):
        self.reaching = set(reaching)
        self.records, self.episodes = [{"random": True}], ["random"]
        self.summary_fields = {"damage_at_episode": None, "episodes_to_recover": None}
        self.task_state = {}
        for _ in range(done):
            self.run_learned_episode()

    def run_learned_episode(self):
        self.records.append({"random": False})
        self.episodes.append(len(self.records) - 1)  # the learned episode's number

    def episode_solved(self, episode):
        return episode != "random" and episode in self.reaching

    def solved_at_episode(self):
        return None

    def save_progress(self):
        pass


@pytest.mark.parametrize("flags, reaching, done, learned", [
    ([], {1}, 0, 1),  # stop at the first episode that reached
    ([], {3}, 0, 3),
    ([], set(), 0, 3),  # never reached: every healthy episode (the reacher's budget)
    (["--min-healthy-episodes", "3"], {1}, 0, 3),  # reached early, more data anyway
    (["--min-healthy-episodes", "3", "--healthy-episodes", "4"], {4}, 0, 4),
    (["--min-healthy-episodes", "3"], {1}, 2, 3),  # resumed after two: one more
    (["--min-healthy-episodes", "6"], {1}, 0, 3),  # capped by --healthy-episodes
    (["--healthy-episodes", "0"], set(), 0, 0),
])
def test_the_adaptation_damages_the_arm_after_its_healthy_episodes(flags, reaching, done,
                                                                   learned, monkeypatch):
    """The schedule's healthy episodes: learned ones until one reached and at least
    ``--min-healthy-episodes`` ran, at most ``--healthy-episodes``; then the damage."""
    from pilco.tasks import adaptation

    damaged = []
    monkeypatch.setattr(adaptation, "damage", lambda run, s: damaged.append(len(run.episodes)))
    for name in ("restart_after_damage", "per_output_noise", "stop_stuck_joints"):
        monkeypatch.setattr(adaptation, name, lambda *a: None)
    schedule = adaptation.AdaptationSchedule()
    schedule.settings = ADAPTATION.parse(flags)
    run = _HealthyRun(reaching, done)
    while schedule.before_episode(run, len(run.episodes) + 1) and not damaged:
        run.run_learned_episode()
    assert len(run.records) - 1 == learned
    assert damaged == [learned + 1] and run.summary_fields["damage_at_episode"] == learned + 2


def test_the_damage_flag_gets_a_learnable_lengthscale_once_damaged_data_arrive():
    from pilco.tasks import adaptation_model

    rng = np.random.default_rng(0)
    X, Y = rng.normal(size=(12, 18)), 0.01 * rng.normal(size=(12, 11))
    X[:, 10] = 0.0  # the flag: healthy transitions only
    args = REACHER.parse(["--basis-functions", "3"])
    agent = reacher_agent.agent_builder(args, np.array([1.2, 0.38, 0.38]), LIMITS)(
        (X, Y), np.append(X[0, :10], 0.0)[None, :])

    def flag_lengthscales():
        return np.array([m.kernel.lengthscales.numpy()[10] for m in agent.mgpr.models])

    np.testing.assert_allclose(flag_lengthscales(), 100.0, rtol=1e-12)  # constant: ignored
    adaptation_model.learn_the_flag(agent)
    agent.set_data((X, Y))
    np.testing.assert_allclose(flag_lengthscales(), 100.0, rtol=1e-12)
    damaged = X.copy()
    damaged[8:, 10] = 1.0
    agent.set_data((damaged, Y))
    np.testing.assert_allclose(flag_lengthscales(), 1.0, rtol=1e-12)
    agent.mgpr.models[0].kernel.lengthscales.assign(np.full(18, 3.0))  # as if trained
    agent.set_data((damaged, Y))
    assert flag_lengthscales()[0] == pytest.approx(3.0, rel=1e-12)


@pytest.mark.parametrize("which", ["all", "main"])
def test_the_adaptation_can_keep_only_the_main_cost_after_the_damage(which):
    pytest.importorskip("mujoco")
    from types import SimpleNamespace

    from pilco.envs import FETCH_ID
    from pilco.experiment import make_env
    from pilco.tasks import adaptation

    healthy = ["--fine-cost-width", "0.05", "--limit-cost", "0.1"]
    args = ADAPTATION.parse([*healthy, "--damaged-cost", which])
    agent = tiny_agent(healthy)
    combined, main = agent.reward, reacher_agent.main_position_reward(agent.reward)
    before = agent.expected_return()
    exp = SimpleNamespace(agent=agent, episodes=[], episode_seed=lambda n: n,
                          make_env=lambda: make_env(FETCH_ID, reacher.env_kwargs(args, False)))
    adaptation.damage(exp, args)
    assert agent.m_init.shape == (1, 10) and agent.m_init[0, 0] != 1.0  # the arm's start
    if which == "all":
        assert agent.reward is combined
    else:
        assert agent.reward is main and type(main).__name__ == "ExponentialReward"
        np.testing.assert_allclose(main.W.numpy(), reacher_agent.position_weights(10, 0.2))
        agent.m_init = np.concatenate([[1.0, 0.5, 0.6], np.zeros(7)])[None, :]
        assert abs(agent.expected_return() - before) > 1e-6  # the objective changed
    assert ADAPTATION.parse([]).damaged_cost == "all"


@pytest.mark.parametrize("restarts", [1, 3])
def test_the_adaptation_restarts_its_policy_search_from_the_second_damaged_episode(
        tmp_path, monkeypatch, restarts):
    """``--damaged-policy-restarts N``: episodes 1 (random) and 2 (healthy, reaches) and
    the first damaged episode 3 (its model knows only the healthy arm) search once;
    damaged episodes 4 and 5 search N times, also after a resume before episode 5."""
    import argparse

    from test_hard_kill import AdaptationTask

    monkeypatch.setattr(os, "fsync", lambda fd: None)
    built = []
    task = AdaptationTask(built)
    task.args = argparse.Namespace(**{**vars(AdaptationTask.args), "damaged_episodes": 2,
                                      "no_stop_when_recovered": True,
                                      "damaged_policy_restarts": restarts})
    summary = task.run(task.new(tmp_path))
    assert summary["damage_at_episode"] == 3 and len(summary["episodes"]) == 4
    assert built[-1].policy_restarts == [1, 1, restarts]  # episodes 2, 3, 4

    resumed = task.resume(tmp_path)  # a fresh config: no restarts until the damage is known
    assert resumed.config.policy_restarts == 1
    task.args.damaged_episodes = 3
    summary = task.run(resumed)
    assert len(summary["episodes"]) == 5
    assert resumed.agent.policy_restarts[-1] == restarts  # episode 5
    if restarts > 1:
        assert (resumed.config.policy_restart_from, resumed.config.policy_restart_when) == (
            4, "always")
    assert ADAPTATION.parse([]).damaged_policy_restarts == 1  # off by default


def priors_of(agent):
    """``[(lengthscale prior, variance prior)]`` per output GP, as (shape, scale) or None."""
    def shape_scale(p):
        return None if p.prior is None else (float(p.prior.concentration.numpy()),
                                             float(1.0 / p.prior.rate.numpy()))
    return [(shape_scale(m.kernel.lengthscales), shape_scale(m.kernel.variance))
            for m in agent.mgpr.models]


def test_the_paper_preset_puts_the_paper_codes_priors_on_every_gp():
    plain, paper = tiny_agent([]), tiny_agent(["--preset", "paper-code"])
    assert priors_of(plain) == [(None, None)] * 10
    assert priors_of(paper) == [((1.0, 10.0), (1.5, 2.0))] * 10
    unset = tiny_agent(["--preset", "paper-code", "--gp-priors", "none"])
    assert priors_of(unset)[0] == (None, None)
    # the priors enter the loss that training minimises: same hyperparameters, the loss
    # differs by exactly the negative log prior density (a finite, nonzero number)
    for a, b in zip(plain.mgpr.models, paper.mgpr.models):
        log_prior = float(b.log_prior_density().numpy())
        assert np.isfinite(log_prior) and log_prior != 0.0
        assert float(b.training_loss().numpy()) == pytest.approx(
            float(a.training_loss().numpy()) - log_prior, rel=1e-12)


def test_a_resumed_paper_run_gets_its_priors_back(tmp_path):
    """agent.npz keeps hyperparameter values only: make_experiment puts the priors back
    on the agent it reads, before any training."""
    tiny = ["--preset", "paper-code", "--horizon", "4", "--planning-horizon", "3",
            "--basis-functions", "2", "--policy-iters", "1", "--policy-iters-first", "1",
            "--model-iters", "2", "--quiet", "--no-render", "--no-figures",
            "--output", str(tmp_path)]
    first = REACHER.experiment(REACHER.parse([*tiny, "--episodes", "2"]))
    first.run()
    assert priors_of(first.agent)[0] == ((1.0, 10.0), (1.5, 2.0))
    resumed = REACHER.experiment(
        REACHER.parse([*tiny, "--episodes", "3", "--resume", str(tmp_path)]))
    x = first.episodes[-1].states[-1]  # read from agent.npz, not rebuilt: the same policy
    np.testing.assert_allclose(resumed.agent.compute_action(x), first.agent.compute_action(x))
    assert priors_of(resumed.agent) == [((1.0, 10.0), (1.5, 2.0))] * 10


@pytest.mark.parametrize("mode", ["stuck", "straight"])
def test_a_resumed_damaged_run_keeps_its_damage_mode(mode, tmp_path):
    """The damage mode is saved with the run's settings; a resumed run's env has it."""
    tiny = ["--horizon", "4", "--planning-horizon", "3", "--basis-functions", "2",
            "--policy-iters", "1", "--model-iters", "2", "--quiet", "--no-render",
            "--no-figures", "--output", str(tmp_path)]
    # the random episode, saved; then the resumed run's learned one
    first = DAMAGED_REACHER.experiment(
        DAMAGED_REACHER.parse([*tiny, "--episodes", "1", "--damage-mode", mode]))
    first.run()
    elbow = first.episodes[-1].states[:, 3 + 3]
    np.testing.assert_allclose(elbow, 2.0 if mode == "stuck" else 0.0)
    args = DAMAGED_REACHER.parse([*tiny, "--episodes", "2", "--resume", str(tmp_path)])
    assert args.damage_mode == mode
    resumed = DAMAGED_REACHER.experiment(args)
    assert resumed.make_env().unwrapped.damage_mode == mode
    resumed.run()
    assert len(resumed.episodes) == 2 and not resumed.episodes[-1].random
    np.testing.assert_allclose(resumed.episodes[-1].states[:, 3 + 3], elbow[0])


def test_a_run_saved_with_the_straight_arms_earlier_name_resumes(tmp_path):
    import json

    saved = settings_to_dict(DAMAGED_REACHER.parse(["--output", str(tmp_path)]))
    saved["damage_mode"] = "zero"  # the straightened arm's earlier name
    (tmp_path / "progress.json").write_text(json.dumps({"settings": saved}))
    args = DAMAGED_REACHER.parse(["--resume", str(tmp_path)])
    kw = reacher.env_kwargs(args, damaged=True)
    from pilco.envs import FetchJointReacher

    assert FetchJointReacher(damaged_joints=kw["damaged_joints"],
                             damage_mode=kw["damage_mode"]).damage_mode == "straight"


def test_a_drawn_target_comes_from_the_seed_and_stays_in_its_cube():
    from pilco.envs.fetch_reacher import DEFAULT_TARGET

    def target(*flags):
        return reacher.env_kwargs(REACHER.parse(list(flags)), False).get("target")

    assert target() is None and target("--seed", "3") is None  # the env's default
    assert target("--target", "1.0", "0.5", "0.4") == (1.0, 0.5, 0.4)
    drawn = {s: np.array(target("--seed", str(s), "--target-spread", "0.15")) for s in range(8)}
    for t in drawn.values():
        assert np.all(np.abs(t - DEFAULT_TARGET) <= 0.15)
    assert len({tuple(t) for t in drawn.values()}) == 8  # every seed its own target
    np.testing.assert_array_equal(drawn[3], target("--seed", "3", "--target-spread", "0.15"))
    # around --target, and the draw scales with the spread
    near = np.array(target("--seed", "3", "--target", "1.0", "0.5", "0.4",
                           "--target-spread", "0.05"))
    np.testing.assert_allclose(near - [1.0, 0.5, 0.4], (drawn[3] - DEFAULT_TARGET) / 3,
                               atol=1e-15)
    # the damaged arm and the adaptation read the same flag
    damaged = DAMAGED_REACHER.parse(["--seed", "3", "--target-spread", "0.15"])
    np.testing.assert_array_equal(reacher.env_kwargs(damaged, True)["target"], drawn[3])
    adapting = ADAPTATION.parse(["--seed", "3", "--target-spread", "0.15"])
    np.testing.assert_array_equal(reacher.env_kwargs(adapting, False)["target"], drawn[3])
    with pytest.raises(SystemExit):
        REACHER.parse(["--target-spread", "-0.1"])


def test_a_drawn_target_out_of_reach_is_reported(caplog):
    import logging

    from pilco.envs import FETCH_ID
    from pilco.experiment import make_env

    with caplog.at_level(logging.INFO, logger="pilco.tasks.reacher"):
        reacher.check_drawn_target(make_env(FETCH_ID, {"target": (1.25, 0.4, 0.4)}))
        reacher.check_drawn_target(make_env(FETCH_ID, {"target": (3.0, 3.0, 3.0)}))
    near, far = caplog.records
    assert near.levelno == logging.INFO and "reachable in" in near.getMessage()
    assert far.levelno == logging.WARNING and "the success rule allows 15" in far.getMessage()
