"""The adaptation after the damage, on a real agent of a 2-D point whose first actuator
breaks: the per-output weighting of the healthy data (``--changed-output-noise``: the
state dimensions that the damage changed, found from how badly the healthy model explains
the first damaged episode, forget the healthy transitions; the others keep them), through
the experiment's data path (the factors the agent gets, [D, N]) and a resume; the
stuck joint (``--stop-stuck-joints``: an actuator that stopped following its commands is
no longer commanded, and the model sees its commands after the damage as 0); and the
replay of a damaged episode's learning (what ``python -m pilco.diagnose --episode N``
does), which must redo the damage's changes to the agent."""
from __future__ import annotations

import argparse

import gymnasium
import numpy as np
import pytest

from pilco.controllers import LinearController
from pilco.experiment import Experiment, ExperimentConfig, RunHooks, stack_transitions
from pilco.models import PILCO
from pilco.rewards import ExponentialReward
from pilco.tasks import adaptation, adaptation_model
from pilco.tasks.adaptation import ADAPTATION


class PlaneEnv(gymnasium.Env):
    """A point in the plane: ``x' = x + u``; once broken (class-wide, as the arm is for
    every episode after the damage) the first coordinate no longer moves."""

    broken = False
    joint_dims = (0, 1)  # each action moves its own coordinate

    def damage(self, joints, mode):  # the reacher's signature
        PlaneEnv.broken = True

    def __init__(self):
        self.observation_space = gymnasium.spaces.Box(-10, 10, (2,), np.float64)
        self.action_space = gymnasium.spaces.Box(-0.5, 0.5, (2,), np.float64)
        self.x = np.zeros(2)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.x = np.array([0.3, -0.2]) if PlaneEnv.broken else np.zeros(2)
        return self.x.copy(), {"distance": self.distance()}

    def distance(self):
        return float(np.linalg.norm(self.x - 1.0))

    def step(self, action):
        u = np.clip(np.asarray(action, dtype=float), -0.5, 0.5)
        if PlaneEnv.broken:
            u[0] = 0.0
        self.x = self.x + u
        return self.x.copy(), 0.0, False, False, {"distance": self.distance()}


def build(data, start_states):
    return PILCO(data, LinearController(2, 2, seed=0), ExponentialReward(2, t=np.ones(2)),
                 horizon=3, m_init=start_states[:1])


class PlaneHooks(RunHooks):
    """The plane's run: :class:`PlaneEnv`, the agents of ``builder`` (default
    :func:`build`), the adaptation's choice of the model's transitions."""

    def __init__(self, builder=build):
        self.builder = builder

    def make_env(self, run):
        return PlaneEnv()

    def build_agent(self, data, start_states):
        return self.builder(data, start_states)

    def model_data(self, run):
        return adaptation_model.damaged_arm_data(run)


class PlaneAdaptation(adaptation.AdaptationSchedule, PlaneHooks):
    """The adaptation's schedule on the plane, with its settings ``settings``."""

    def __init__(self, settings):
        super().__init__()
        self.settings = settings


def args(**kw):
    base = dict(changed_output_noise=1e6, changed_output_threshold=10.0, old_data_noise=100.0)
    base.update(kw)
    return argparse.Namespace(**base)


@pytest.fixture
def damaged_run(tmp_path):
    """Two healthy random episodes (the model fitted to them), then one on the broken
    arm: the point of the adaptation where the factors are chosen."""
    cfg = ExperimentConfig(task="plane", env_id="unused", seed=1, episodes=4,
                           random_episodes=2, horizon=25, random_action_scale=0.3,
                           predictions=False, quiet=True, render=False)
    exp = Experiment(cfg, str(tmp_path / "run"), PlaneHooks())
    PlaneEnv.broken = False
    try:
        exp.run_random_episode()
        exp.run_random_episode()
        exp.agent.optimize_models(maxiter=200)
        exp.task_state.update(older_noise_scale=100.0, older_before_episode=3)  # as run
        PlaneEnv.broken = True
        exp.run_random_episode()  # the first damaged episode (random here)
    finally:
        PlaneEnv.broken = False
    return exp


def test_the_dimension_the_damage_changed_forgets_the_healthy_data(damaged_run):
    exp = damaged_run
    healthy = 50  # transitions of the two healthy episodes
    # before the choice: every output down-weights the healthy data alike
    np.testing.assert_array_equal(exp.agent.mgpr.noise_scales,
                                  np.r_[np.full(healthy, 100.0), np.ones(25)])
    adaptation_model.per_output_noise(exp, args(), first=3)
    z2 = exp.summary_fields["output_disagreement"]
    # the healthy model predicts the first coordinate moving by u; it stood still
    assert z2[0] > 1e3 and z2[1] < 10.0, z2
    assert exp.task_state["older_noise_scale"] == [1e6, 100.0]
    want = np.stack([np.r_[np.full(healthy, 1e6), np.ones(25)],
                     np.r_[np.full(healthy, 100.0), np.ones(25)]])
    np.testing.assert_array_equal(exp.agent.mgpr.noise_scales, want)  # [D, N]
    # chosen once: a later call (every damaged episode calls it) changes nothing
    exp.task_state["older_noise_scale"] = 7.0
    adaptation_model.per_output_noise(exp, args(changed_output_noise=5.0), first=3)
    assert exp.task_state["older_noise_scale"] == 7.0
    # the stuck coordinate's model now predicts it standing still where the healthy
    # data said it moves
    exp.task_state["older_noise_scale"] = [1e6, 100.0]
    exp.give_agent_data(exp.agent)
    exp.agent.optimize_models(maxiter=200)
    X = np.array([[0.0, 0.0, 0.3, 0.3]])
    mean, _ = exp.agent.one_step_prediction(X)
    assert abs(mean[0, 0]) < 0.03 and abs(mean[0, 1] - 0.3) < 0.03, mean


def test_the_disagreement_is_about_one_where_the_model_knew_the_dynamics(damaged_run):
    exp = damaged_run
    healthy = [e.transitions() for e in exp.episodes[:2]]
    z2 = adaptation_model.output_disagreement(exp.agent, healthy[0], healthy[1])
    assert np.all(z2 < 10.0), z2
    # without the option, or before the damaged episode, nothing is chosen
    for a, first in ((args(changed_output_noise=None), 3), (args(), 4)):
        adaptation_model.per_output_noise(exp, a, first=first)
        assert "output_disagreement" not in exp.summary_fields
        assert exp.task_state["older_noise_scale"] == 100.0


def test_a_resumed_run_keeps_the_factors_per_output(damaged_run):
    exp = damaged_run
    adaptation_model.per_output_noise(exp, args(), first=3)
    exp.save_progress()
    agents = []

    def rebuild(data, start_states):
        agents.append(build(data, start_states))
        return agents[-1]

    resumed = Experiment.resume(exp.directory, exp.config, PlaneHooks(rebuild))
    assert resumed.task_state["older_noise_scale"] == [1e6, 100.0]
    np.testing.assert_array_equal(resumed.agent.mgpr.noise_scales,
                                  exp.agent.mgpr.noise_scales)
    assert resumed.summary_fields["output_disagreement"] == \
        exp.summary_fields["output_disagreement"]


def test_a_run_saved_before_task_state_resumes_with_its_state(damaged_run):
    """Older versions wrote the data state as fields of progress.json's own (and
    ``train_from_episode`` under ``extra``): a resume reads them into ``task_state``,
    without the store knowing a task's names; every field today's runs write is known."""
    import json

    from pilco.experiment.store import PROGRESS_FIELDS, progress_record

    exp = damaged_run
    exp.task_state["train_from_episode"] = 2
    exp.save_progress()
    assert set(progress_record(exp)) <= PROGRESS_FIELDS
    path = exp.store.path("progress.json")
    progress = json.load(open(path))
    state = progress.pop("task_state")
    assert state["older_noise_scale"] == 100.0
    train_from = state.pop("train_from_episode")
    assert train_from == 2
    progress.update(state, extra={"train_from_episode": train_from})
    json.dump(progress, open(path, "w"))
    resumed = Experiment.resume(exp.directory, exp.config, PlaneHooks(build))
    assert resumed.task_state == {**state, "train_from_episode": train_from}


@pytest.mark.parametrize("episode, restarts, stop", [(3, 1, False), (4, 2, False),
                                                     (4, 1, True)])
def test_replaying_a_damaged_episode_redoes_the_damage(tmp_path, episode, restarts, stop):
    """The adaptation's schedule on the plane: a random and a healthy episode, the damage (the
    broken plane starts elsewhere: the agent's ``m_init`` changes), two damaged episodes
    (with ``--damaged-policy-restarts 2`` the second one's policy search restarts; with
    ``--stop-stuck-joints`` the second one no longer commands the stuck coordinate).
    Replaying the learning up to a damaged episode (the diagnosis of an earlier episode)
    gives the policy that ran it only with the task's replay hook."""
    from pilco.diagnose.replay import action_error, replay_learning

    cfg = ExperimentConfig(task="plane", env_id="unused", seed=2, episodes=4,
                           random_episodes=1, horizon=8, random_action_scale=0.3,
                           model_iters=20, policy_iters=5, predictions=False, quiet=True,
                           render=False)
    run_args = argparse.Namespace(
        random_episodes=1, healthy_episodes=1, damaged_episodes=2, damaged_joints=["x"],
        damage_mode="stuck", drop_old_data=False, no_stop_when_recovered=False,
        min_healthy_episodes=1, damaged_cost="all", damage_input=False,
        old_data_noise=100.0, damaged_policy_restarts=restarts, changed_output_noise=None,
        changed_output_threshold=10.0, stop_stuck_joints=stop, stuck_joint_ratio=0.1,
        replan_stuck_joints=False)  # a re-planned episode is not replayed (its docstring)
    exp = Experiment(cfg, str(tmp_path / "run"), PlaneAdaptation(run_args))
    PlaneEnv.broken = False
    try:
        summary = exp.run()
    finally:
        PlaneEnv.broken = False
    assert summary["damage_at_episode"] == 3 and len(exp.episodes) == 4
    np.testing.assert_array_equal(exp.agent.m_init, [[0.3, -0.2]])
    if stop:
        assert summary["stuck_joints"] == [0] and exp.task_state["inert_actions"] == [0]
        assert np.all(exp.episodes[2].actions[:, 0] != 0.0)  # sent, with no effect
        np.testing.assert_array_equal(exp.episodes[3].actions[:, 0], 0.0)  # not sent
    else:
        assert "stuck_joints" not in summary
    view = replay_learning(exp, episode)
    np.testing.assert_array_equal(view.agent.m_init, [[0.3, -0.2]])
    assert view.config.policy_restarts_at(episode, False) == (restarts if episode == 4 else 1)
    assert action_error(view.agent, exp.episodes[episode - 1]) < 1e-9
    exp.hooks = PlaneHooks()  # without the adaptation's replay: the healthy start, another policy
    view = replay_learning(exp, episode)
    np.testing.assert_array_equal(view.agent.m_init, [[0.0, 0.0]])
    assert action_error(view.agent, exp.episodes[episode - 1]) > 1e-6


def test_the_disagreement_takes_a_noise_variance_on_its_floor(damaged_run):
    """A noise variance fitted down to its floor is copied exactly (unconstrained), where
    assigning the constrained value would fail (its transform's inverse is -inf)."""
    exp = damaged_run
    noise = exp.agent.mgpr.models[1].likelihood.variance
    noise.unconstrained_variable.assign(-60.0)
    assert noise.numpy() == exp.agent.mgpr.noise_floor
    healthy = [e.transitions() for e in exp.episodes[:2]]
    z2 = adaptation_model.output_disagreement(exp.agent, healthy[0], healthy[1])
    assert np.all(np.isfinite(z2)) and z2.shape == (2,)


def stuck_args(**kw):
    base = dict(stop_stuck_joints=True, stuck_joint_ratio=0.1)
    base.update(kw)
    return argparse.Namespace(**base)


def test_a_stuck_joint_is_no_longer_commanded(damaged_run):
    exp = damaged_run
    healthy = 50  # transitions of the two healthy episodes
    ratios = adaptation_model.joint_follow_ratios(exp.episodes[:2], PlaneEnv.joint_dims)
    np.testing.assert_allclose(ratios, 1.0, rtol=1e-9)  # x' = x + u, no limits
    sent = exp.episodes[2].actions[:, 0].copy()
    assert np.all(sent != 0.0)
    for a in (stuck_args(stop_stuck_joints=False), stuck_args()):
        adaptation_model.stop_stuck_joints(exp, a, first=4)  # before the first damaged episode
        assert "stuck_joints" not in exp.summary_fields
        assert exp.task_state["inert_actions"] == []
    adaptation_model.stop_stuck_joints(exp, stuck_args(), first=3)
    fields = exp.summary_fields
    assert fields["stuck_joints"] == [0] and exp.task_state["inert_actions"] == [0]
    assert fields["joint_follow_ratio"][0] == 0.0
    assert fields["joint_follow_ratio"][1] == pytest.approx(1.0)
    agent = exp.agent
    np.testing.assert_array_equal(agent.controller.max_action, [0.0, 1.0])
    assert agent.compute_action(np.array([[0.2, 0.7]]))[0, 0] == 0.0
    # the model: the healthy data as sent and as equals, the damaged commands as 0
    X, _ = agent.data
    np.testing.assert_array_equal(X[:healthy], exp.episodes[0].transitions()[0].tolist()
                                  + exp.episodes[1].transitions()[0].tolist())
    np.testing.assert_array_equal(X[healthy:, 2], 0.0)
    np.testing.assert_array_equal(X[healthy:, 3], exp.episodes[2].actions[:, 1])
    np.testing.assert_array_equal(agent.mgpr.noise_scales, np.ones(healthy + 25))
    np.testing.assert_array_equal(exp.episodes[2].actions[:, 0], sent)  # the record keeps them
    # with the stuck coordinate's commands at 0 every transition tells the same story: the
    # refitted model has the first coordinate stay where it starts under any policy
    agent.optimize_models(maxiter=200)
    m, _, _ = agent.predict(np.array([[0.3, -0.2]]), 0.01 * np.eye(2), 3)
    assert abs(m[0, 0] - 0.3) < 0.03, m
    # found once: later calls (after every damaged episode) keep the choice
    exp.task_state["inert_actions"] = [0]
    adaptation_model.stop_stuck_joints(exp, stuck_args(stuck_joint_ratio=2.0), first=3)
    assert fields["stuck_joints"] == [0]


def test_a_healthy_joint_stays_commanded_and_the_flags_exclude_each_other(damaged_run):
    exp = damaged_run
    ratios = adaptation_model.joint_follow_ratios(exp.episodes[2:], PlaneEnv.joint_dims)
    # a joint that never followed its commands on the healthy arm is not called stuck;
    # one that did in any healthy episode is (a joint may sit at a limit for a whole one)
    assert adaptation_model.stuck_joints(exp.episodes[2:], exp.episodes[2:], 0.1,
                                   PlaneEnv.joint_dims) == []
    for healthy in (exp.episodes[:2], exp.episodes[1:]):
        assert adaptation_model.stuck_joints(healthy, exp.episodes[2:], 0.1,
                                       PlaneEnv.joint_dims) == [0]
    assert ratios[0] == 0.0 and np.isnan(adaptation_model.joint_follow_ratios(
        [exp.episodes[2]], (1, 0))).sum() == 0
    out = ["--output", str(exp.directory) + "-x"]
    assert ADAPTATION.parse(out).stop_stuck_joints  # the default
    assert not ADAPTATION.parse(["--no-stop-stuck-joints", *out]).stop_stuck_joints
    # the paper code's arm reports commanded angles, which follow a stuck joint's commands
    paper = ADAPTATION.parse(["--preset", "paper-code", *out])
    assert paper.joint_state == "commanded" and not paper.stop_stuck_joints
    assert ADAPTATION.parse(["--no-stop-stuck-joints", "--changed-output-noise", "1e6",
                                  *out]).changed_output_noise == 1e6
    for clash in (["--changed-output-noise", "1e6"], ["--joint-state", "commanded"]):
        with pytest.raises(SystemExit):
            ADAPTATION.parse([*clash, *out])


def test_a_resumed_run_keeps_the_stuck_joint_stopped(damaged_run):
    exp = damaged_run
    adaptation_model.stop_stuck_joints(exp, stuck_args(), first=3)
    exp.save()
    resumed = Experiment.resume(exp.directory, exp.config, PlaneHooks())
    assert (resumed.task_state["inert_actions"], resumed.task_state["inert_from_episode"]) == (
        [0], 3)
    np.testing.assert_array_equal(resumed.training_data()[0], exp.training_data()[0])
    adaptation_model.stop_stuck_joints(resumed, stuck_args(), first=3)  # as the schedule does
    np.testing.assert_array_equal(resumed.agent.controller.max_action, [0.0, 1.0])
    np.testing.assert_array_equal(resumed.agent.data[0], exp.agent.data[0])


def _episode(steps, start):
    from pilco.experiment import Episode

    states = start + np.arange(steps + 1, dtype=float)[:, None] * np.ones((1, 2))
    return Episode(states=states, actions=np.full((steps, 2), 0.5), rewards=np.zeros(steps),
                   distances=np.zeros(steps + 1))


@pytest.mark.parametrize("train_from, max_data", [(1, None), (2, None), (1, 9)])
def test_older_episodes_are_down_weighted_against_newer_ones_only(train_from, max_data):
    """The adaptation's choice of model data: from ``train_from_episode`` on, the first
    ``max_data``; the episodes before ``older_before_episode`` (the healthy arm's) get
    ``older_noise_scale``, unless no later transition is among them."""
    from types import SimpleNamespace

    episodes = [_episode(4, 0.0), _episode(3, 10.0)]
    record = SimpleNamespace(episodes=episodes, config=SimpleNamespace(max_data=max_data),
                             task_state=dict(older_noise_scale=50.0, older_before_episode=3,
                                             train_from_episode=train_from))
    old = [e.steps for e in episodes][train_from - 1:]
    X, Y, scales = adaptation_model.damaged_arm_data(record)
    # no transition of episode 3 or later yet: nothing to weigh against, all ones
    np.testing.assert_array_equal(scales, np.ones(len(X)))
    assert len(X) == min(sum(old), max_data or 99)
    episodes.append(_episode(2, 20.0))
    X, Y, scales = adaptation_model.damaged_arm_data(record)
    want = np.r_[np.full(sum(old), 50.0), np.ones(2)][:max_data]
    if not np.any(want == 1.0):  # max_data keeps old transitions only
        want = np.ones_like(want)
    np.testing.assert_array_equal(scales, want)
    assert len(X) == len(Y) == len(want)
    np.testing.assert_array_equal(X[0], stack_transitions(episodes[train_from - 1:])[0][0])
    # one factor per output dimension: [D, N]
    record.task_state["older_noise_scale"] = [50.0, 2.0]
    scales = adaptation_model.damaged_arm_data(record)[2]
    assert scales.shape == (2, len(want))
    # inert actions read as 0 from their episode on; the episodes keep what was sent
    record.task_state.update(inert_actions=[1], inert_from_episode=3)
    X, _, _ = adaptation_model.damaged_arm_data(record)
    n = len(X)
    if max_data is None:
        np.testing.assert_array_equal(X[-2:, 2 + 1], 0.0)
        np.testing.assert_array_equal(X[:n - 2, 2 + 1], 0.5)
    assert np.all(episodes[2].actions == 0.5)


def replan_args(**kw):
    base = dict(stop_stuck_joints=True, stuck_joint_ratio=0.1, stuck_check_steps=3)
    base.update(kw)
    return argparse.Namespace(**base)


def _healthy_run(tmp_path):
    """Two healthy random episodes and a fitted model, as before the first damaged
    episode (episode 3): the point where the replanning watch runs."""
    cfg = ExperimentConfig(task="plane", env_id="unused", seed=1, episodes=4,
                           random_episodes=2, horizon=12, random_action_scale=0.3,
                           predictions=False, quiet=True, render=False, policy_iters=5)
    exp = Experiment(cfg, str(tmp_path / "run"), PlaneHooks())
    PlaneEnv.broken = False
    exp.run_random_episode()
    exp.run_random_episode()
    exp.agent.optimize_models(maxiter=100)
    exp.agent.controller.max_action = np.array([0.5, 0.5])
    exp.agent.controller.b.assign([[0.3, 0.3]])  # both actuators clearly commanded
    exp.agent.retrace()
    return exp


@pytest.mark.parametrize("broken", [True, False])
def test_the_first_damaged_episode_replans_once_a_joint_is_stuck(tmp_path, monkeypatch,
                                                                 broken):
    """On the broken plane the watch finds the first actuator stuck after 3 steps, stops
    commanding it, searches the policy from the state reached (the agent's start state
    is restored after) and the episode goes on with it; on the healthy plane it only
    watches."""
    exp = _healthy_run(tmp_path)
    agent = exp.agent
    start = agent.m_init.copy()
    searched = []
    search = agent.optimize_policy

    def optimize_policy(**kw):
        searched.append((agent.m_init.copy(), kw["maxiter"]))
        return search(**kw)

    monkeypatch.setattr(agent, "optimize_policy", optimize_policy)
    PlaneEnv.broken = broken
    try:
        watch = adaptation_model.ReplanWhenStuck(exp, replan_args(), first=3, number=3)
        exp.policy_notes = {}
        ep = exp._interact(3, watch(lambda x: agent.compute_action(x)[0]))
    finally:
        PlaneEnv.broken = False
    np.testing.assert_array_equal(agent.m_init, start)
    if not broken:
        assert searched == [] and "replanned" not in exp.policy_notes
        assert "stuck_joints" not in exp.summary_fields
        assert np.all(ep.actions[:, 0] != 0.0)
        return
    assert np.all(np.abs(ep.actions[:3, 0]) > 0.0)  # commanded while it was watched
    np.testing.assert_array_equal(ep.actions[3:, 0], 0.0)  # then no longer
    np.testing.assert_array_equal(ep.states[:, 0], ep.states[0, 0])  # it never moved
    assert len(searched) == 1
    np.testing.assert_array_equal(searched[0][0], ep.states[3][None, :])  # from there
    assert searched[0][1] == exp.config.policy_iterations(3)
    note = exp.policy_notes["replanned"]
    assert note["step"] == 3 and note["stuck_joints"] == [0]
    assert exp.summary_fields["stuck_joints"] == [0]
    assert exp.task_state["inert_actions"] == [0] and exp.task_state["inert_from_episode"] == 3
    # the pause is the loop's policy time; the episode's record keeps the note and counts
    # the search's evaluations; the model sees the stuck commands as 0
    paused = exp.policy_notes.pop("paused_seconds")
    assert paused == pytest.approx(note["seconds"], abs=0.01) and paused < ep.seconds
    exp._add_episode(ep, {"interaction": ep.seconds - paused}, {}, policy_evaluations=0)
    assert exp.records[-1]["replanned"]["stuck_joints"] == [0]
    assert exp.records[-1]["policy_evaluations"] == agent.policy_evaluations > 0
    np.testing.assert_array_equal(agent.data[0][50:, 2], 0.0)
    # after the episode, stop_stuck_joints keeps the joints found mid-episode
    adaptation_model.stop_stuck_joints(exp, stuck_args(), first=3)
    assert exp.summary_fields["stuck_joints"] == [0]
    np.testing.assert_array_equal(agent.controller.max_action, [0.0, 0.5])


def test_the_adaptation_watches_only_its_first_damaged_episode():
    run = argparse.Namespace(summary_fields={"damage_at_episode": None}, episodes=[1, 2],
                             make_env=PlaneEnv)

    def policy(x):
        return x

    on = ADAPTATION.parse(["--output", "x"])
    assert on.replan_stuck_joints and on.stuck_check_steps == 3
    hooks = PlaneAdaptation(on)
    assert hooks.watch(run, 3, policy) is policy  # healthy: not damaged yet
    run.summary_fields["damage_at_episode"] = 3
    assert hooks.watch(run, 3, policy) is not policy  # the first damaged episode
    for off in ("--no-replan-stuck-joints", "--no-stop-stuck-joints"):
        other = PlaneAdaptation(ADAPTATION.parse([off, "--output", "x"]))
        assert other.watch(run, 3, policy) is policy
    run.summary_fields["stuck_joints"] = []  # judged after the first damaged episode
    assert hooks.watch(run, 4, policy) is policy
