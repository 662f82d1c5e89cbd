"""Unit tests of the experiment loop, in-process, with a tiny environment and a stand-in
agent: what a run collects, saves and summarises, the model-refit rule, interrupts by
Ctrl-C and SIGTERM, and resuming."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys

import gymnasium
import numpy as np
import pytest

from pilco.experiment import (Experiment, ExperimentConfig, RunHooks, RunStore, rollout,
                              stack_transitions)
from pilco.experiment import signals as run_signals


class LineEnv(gymnasium.Env):
    """A point on a line: ``x' = x + u``; the distance is ``|x - 1|``."""

    def __init__(self):
        self.observation_space = gymnasium.spaces.Box(-10, 10, (1,), np.float64)
        self.action_space = gymnasium.spaces.Box(-0.5, 0.5, (1,), np.float64)
        self.x = np.zeros(1)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.x = np.array([0.01 * (seed or 0) % 0.1])
        return self.x.copy(), {"distance": float(abs(self.x[0] - 1))}

    def step(self, action):
        self.x = self.x + np.clip(action, -0.5, 0.5)
        d = float(abs(self.x[0] - 1))
        return self.x.copy(), -d, d < 0.05, False, {"distance": d}


class StandInAgent:
    """Records what the loop asks of an agent; acts with a fixed gain towards 1."""

    horizon = 5

    def __init__(self, data, gain=0.6, interrupt_policy_at=None):
        self.calls = []
        self.data = data
        self.gain = gain
        self.interrupt_policy_at = interrupt_policy_at
        self.m_init = np.zeros((1, 1))
        self.policy_restarts = []  # the restarts each policy search was asked for

    def set_data(self, data, noise_scales=None):
        self.data = (np.array(data[0]), np.array(data[1]))
        self.noise_scales = np.ones(len(data[0])) if noise_scales is None else noise_scales
        self.calls.append(("set_data", len(data[0])))

    def optimize_models(self, maxiter, restarts, seed, callback, min_rel_improvement, patience):
        self.calls.append(("models", seed))
        callback(0)

    def optimize_policy(self, maxiter, restarts, seed, callback, method, min_rel_improvement,
                        patience):
        self.calls.append(("policy", seed, min_rel_improvement))
        self.policy_restarts.append(restarts)
        if self.interrupt_policy_at == len([c for c in self.calls if c[0] == "policy"]):
            os.kill(os.getpid(), signal.SIGTERM)  # arrives mid-optimisation
        callback(0)
        return 1.0

    def compute_action(self, x):
        return np.array([[self.gain * (1.0 - float(np.ravel(x)[0]))]])

    def predict_trajectory_with_rewards(self, horizon):
        return (np.zeros((horizon + 1, 1)), np.ones((horizon + 1, 1, 1)),
                np.zeros(horizon + 1), np.zeros(horizon + 1))

    def save(self, path):
        raise NotImplementedError("the stand-in agent is rebuilt on resume")


def config(**kw):
    base = dict(task="line", env_id="unused", seed=3, episodes=4, random_episodes=1, horizon=6,
                random_action_scale=0.1, predictions=False, quiet=True, render=False,
                success_threshold=0.05)
    base.update(kw)
    return ExperimentConfig(**base)


class LineHooks(RunHooks):
    """The line task's hooks: :class:`LineEnv`, the agent builder ``build`` and the hooks
    given as functions in ``methods`` (each with the method's arguments after ``self``)."""

    def __init__(self, build, **methods):
        self._build = build
        for name, function in methods.items():
            assert callable(getattr(RunHooks, name)), name
            setattr(self, name, function)

    def make_env(self, run):
        return LineEnv()

    def build_agent(self, data, start_states):
        return self._build(data, start_states)


def experiment(tmp_path, cfg=None, agents=None, agent_kw=None, agent_class=None, **kw):
    """An experiment on the line task whose agents (``agent_class``, by default
    :class:`StandInAgent`) are appended to ``agents`` as it builds them; ``kw``: hooks as
    functions (:class:`LineHooks`)."""
    agents = [] if agents is None else agents
    agent_class = agent_class or StandInAgent

    def build(data, start_states):
        assert start_states.shape[1] == 1 and len(start_states) >= cfg_.random_episodes
        agents.append(agent_class(data, **(agent_kw or {})))
        return agents[-1]

    cfg_ = cfg or config()
    return Experiment(cfg_, str(tmp_path / "run"), LineHooks(build, **kw)), agents


def test_a_run_collects_saves_and_summarises_every_episode(tmp_path):
    exp, agents = experiment(tmp_path)
    summary = exp.run()
    agent = agents[0]
    steps = [r["steps"] for r in summary["episodes"]]
    # the agent was built once, after the random episode, and saw every transition
    assert len(agents) == 1 and agent.data[0].shape == (sum(steps), 2)
    assert [c for c in agent.calls if c[0] == "models"] == [("models", 3002), ("models", 3003),
                                                            ("models", 3004)]
    assert summary["complete"] is True and summary["seed"] == 3
    assert [r["random"] for r in summary["episodes"]] == [True, False, False, False]
    # the gain-0.6 policy reaches 5 cm of x = 1 in 4 steps (actions clipped to 0.5)
    assert summary["solved"] and summary["solved_at_episode"] == 2 and summary["success"]
    for record, distances in zip(summary["episodes"], summary["distances"]):
        assert len(distances) == record["steps"] + 1
        assert record["min_distance"] == pytest.approx(min(distances[1:]))
    with np.load(exp.store.data_path) as data:
        assert data["X"].shape == (sum(steps), 2)
        np.testing.assert_array_equal(np.bincount(data["episode"])[1:], steps)
        np.testing.assert_allclose(data["Y"][:, 0], np.concatenate(
            [np.diff(data[f"states_{i}"][:, 0]) for i in range(1, 5)]))
    progress = json.load(open(exp.store.progress_path))
    assert progress["episodes_done"] == 4 and progress["complete"] is True
    assert json.load(open(exp.store.summary_path)) == json.loads(json.dumps(summary))
    # where the numbers came from: this checkout's commit, the versions, the CPU
    prov = summary["provenance"]
    assert prov["versions"]["numpy"] == np.__version__ and prov["cpu"]
    if prov["git"] is not None:
        assert len(prov["git"]["commit"]) == 40 and isinstance(prov["git"]["dirty"], bool)


def test_an_unchanged_training_set_is_not_refitted(tmp_path):
    exp, agents = experiment(tmp_path, config(max_data=4, episodes=5))
    exp.run()
    # 6 random transitions already exceed max_data=4: one fit, then the data never change
    assert [c[0] for c in agents[0].calls].count("models") == 1
    assert agents[0].data[0].shape == (4, 2)


def test_a_tasks_choice_of_model_data_and_its_state_survive_a_resume(tmp_path):
    """``model_data`` chooses the model's transitions and their noise factors (before the
    ``max_data`` cap); ``task_state`` is saved and read back; the success rule applies."""
    def later_half(record):  # the transitions of episodes >= state["from"], factor 3
        start = record.task_state.get("from", 1)
        X, Y = stack_transitions(record.episodes[start - 1:])
        return X, Y, np.full(len(X), 3.0)

    exp, agents = experiment(tmp_path, config(episodes=4, max_data=5),
                             success=lambda s: len(s["episodes"]) == 4,
                             model_data=later_half)
    exp.run_random_episode()
    exp.run_learned_episode()
    exp.task_state["from"] = 2
    X, _ = exp.training_data()
    assert len(X) == min(5, exp.episodes[1].steps)
    np.testing.assert_array_equal(exp.training_noise_scales(), np.full(len(X), 3.0))
    exp.run_learned_episode()
    np.testing.assert_array_equal(agents[0].noise_scales, np.full(5, 3.0))  # given
    assert exp.summary()["success"] is False
    base, rebuilt = experiment(tmp_path)
    resumed = Experiment.resume(exp.directory, config(episodes=4, max_data=5),
                                LineHooks(base.hooks.build_agent, model_data=later_half,
                                          success=lambda s: len(s["episodes"]) == 4))
    assert resumed.task_state == {"from": 2}
    np.testing.assert_array_equal(rebuilt[0].noise_scales, np.full(5, 3.0))
    resumed.run_learned_episode()
    assert resumed.summary()["success"] is True
    # without a choice: every episode's transitions, factors 1
    plain, _ = experiment(tmp_path / "plain", config(episodes=3))
    plain.run_random_episode()
    plain.run_learned_episode()
    assert len(plain.training_data()[0]) == sum(e.steps for e in plain.episodes)
    np.testing.assert_array_equal(plain.training_noise_scales(),
                                  np.ones(len(plain.training_data()[0])))


def test_ctrl_c_in_a_rollout_keeps_its_transitions_and_the_run_resumes(tmp_path):
    exp, agents = experiment(tmp_path)
    exp.run_random_episode()
    agent = agents[0]
    original = agent.compute_action
    calls = {"n": 0}

    def interrupting(x):
        calls["n"] += 1
        if calls["n"] == 3:
            raise KeyboardInterrupt
        return original(x)

    agent.compute_action = interrupting
    summary = exp.run()
    assert exp.interrupted and summary["complete"] is False and len(summary["episodes"]) == 1
    with np.load(exp.store.data_path) as data:
        assert data["partial_X"].shape == (2, 2)  # two complete steps of episode 2
    agent.compute_action = original

    resumed, new_agents = experiment(tmp_path)
    resumed = Experiment.resume(exp.directory, config(), resumed.hooks)
    assert len(resumed.episodes) == 1 and resumed.agent is new_agents[0]
    np.testing.assert_array_equal(resumed.episodes[0].states, exp.episodes[0].states)
    final = resumed.run()
    assert final["complete"] is True and len(final["episodes"]) == 4
    assert final["episodes"][0] == summary["episodes"][0]


def test_sigterm_stops_at_the_next_safe_point_and_saves(tmp_path):
    exp, agents = experiment(tmp_path, agent_kw={"interrupt_policy_at": 2})
    summary = exp.run()
    assert exp.interrupted and not run_signals.stop_requested()
    # the signal came during episode 3's policy optimisation: two episodes are kept
    assert len(summary["episodes"]) == 2 and summary["complete"] is False
    assert json.load(open(exp.store.progress_path))["interrupted"] is True
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL


def test_an_interrupt_during_a_search_keeps_the_agent_of_the_last_episode(tmp_path):
    """A signal during episode 3's policy search: the agent, halfway through its fit and
    search, is not written over agent.npz, so that --resume redoes episode 3 from the
    agent episode 2 left (the resumed run is then the uninterrupted one)."""
    saved = []

    class Saving(StandInAgent):
        def save(self, path):  # counts the searches the saved agent had been through
            saved.append(len([c for c in self.calls if c[0] == "policy"]))
            with open(path, "wb"):
                pass

    exp, _ = experiment(tmp_path, agent_kw={"interrupt_policy_at": 2}, agent_class=Saving)
    summary = exp.run()
    assert exp.interrupted and len(summary["episodes"]) == 2
    assert saved and saved[-1] == 1 and max(saved) == 1  # episode 2's, never the one cut


def test_resume_reads_progress_written_before_the_typed_fields(tmp_path):
    exp, _ = experiment(tmp_path)
    exp.run_random_episode()
    exp.run_learned_episode()
    progress = json.load(open(exp.store.progress_path))
    progress.pop("task_state")
    progress.pop("summary_fields")
    progress["older_noise_scale"] = 4.0
    progress["extra"] = {"train_from_episode": 2, "summary": {"damage_at_episode": 2}}
    open(exp.store.progress_path, "w").write(json.dumps(progress))
    base, _ = experiment(tmp_path)
    resumed = Experiment.resume(exp.directory, config(), base.hooks)
    assert resumed.task_state == {"train_from_episode": 2, "older_noise_scale": 4.0}
    assert resumed.summary()["damage_at_episode"] == 2


def test_resume_refuses_progress_that_counts_missing_data(tmp_path):
    exp, _ = experiment(tmp_path)
    exp.run_random_episode()
    progress = json.load(open(exp.store.progress_path))
    progress["episodes_done"] = 2
    progress["records"].append(dict(progress["records"][0], episode=2))
    open(exp.store.progress_path, "w").write(json.dumps(progress))
    with pytest.raises(ValueError, match="lacks episode 2"):
        RunStore(exp.directory).load_episodes(progress["records"])


def test_rollout_needs_a_policy_unless_random():
    with pytest.raises(ValueError, match="needs a policy_fn"):
        rollout(LineEnv(), None, 3)
    ep = rollout(LineEnv(), lambda x: np.array([0.5]), 3, seed=0)
    assert ep.steps == 2 and ep.terminated  # 0 -> 0.5 -> 1.0
    X, Y = ep.transitions()
    np.testing.assert_allclose(Y[:, 0], [0.5, 0.5])
    np.testing.assert_allclose(X, [[0.0, 0.5], [0.5, 0.5]])


def test_tasks_entry_point_lists_the_tasks():
    out = subprocess.run([sys.executable, "-m", "pilco.tasks", "nonsense"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2
    from pilco.tasks import TASKS, task_main

    # the usage of `pilco run`, which `python -m pilco.tasks` is
    assert out.stderr.startswith("usage: pilco run TASK")
    assert f"unknown task 'nonsense'; choose one of {', '.join(TASKS)}" in out.stderr

    with pytest.raises(ValueError, match="unknown task 'nonsense'"):
        task_main("nonsense")


def test_the_first_policy_optimisation_can_have_its_own_budget(tmp_path):
    exp, agents = experiment(tmp_path, config(policy_iters=7, policy_iters_first=60))
    seen = []
    exp.run_random_episode()
    agent = agents[0]
    original = agent.optimize_policy

    def recording(maxiter, **kw):
        seen.append(maxiter)
        return original(maxiter, **kw)

    agent.optimize_policy = recording
    exp.run_learned_episode()
    exp.run_learned_episode()
    assert seen == [60, 7]
    two_random = config(policy_iters=7, policy_iters_first=60, random_episodes=2, episodes=4)
    assert [two_random.policy_iterations(n) for n in (3, 4)] == [60, 7]
    assert [two_random.first_learned(n) for n in (2, 3, 4)] == [False, True, False]
    assert config(policy_iters=7).policy_iterations(2) == 7
    with pytest.raises(ValueError, match="policy_iters_first must be a whole number"):
        config(policy_iters_first=0)
    with pytest.raises(ValueError, match="episodes must be a whole number >= 1"):
        config(episodes=0)


def test_policy_restarts_can_stop_once_an_episode_is_solved(tmp_path):
    def restarts_seen(when, gains, start=1):
        exp, agents = experiment(tmp_path / f"{when}-{start}-{gains}",
                                 config(policy_restarts=3, policy_restart_when=when,
                                        policy_restart_from=start))
        seen = []
        exp.run_random_episode()
        agent = agents[0]
        original = agent.optimize_policy

        def recording(maxiter, restarts, **kw):
            seen.append(restarts)
            return original(maxiter, restarts=restarts, **kw)

        agent.optimize_policy = recording
        for gain in gains:  # gain 0: the episode goes nowhere, unsolved
            agent.gain = gain
            exp.run_learned_episode()
        return seen, exp.solved_at_episode()

    assert restarts_seen("always", [0.0, 0.6, 0.6]) == ([3, 3, 3], 3)
    assert restarts_seen("unsolved", [0.0, 0.6, 0.6]) == ([3, 3, 1], 3)
    assert restarts_seen("unsolved", [0.0, 0.0, 0.0]) == ([3, 3, 3], None)
    # restarts from episode 3 on (episodes 2-4 are learned): not in episode 2, and a run
    # solved in episode 2 never restarts
    assert restarts_seen("unsolved", [0.0, 0.0, 0.0], start=3) == ([1, 3, 3], None)
    assert restarts_seen("unsolved", [0.6, 0.0, 0.6], start=3) == ([1, 1, 1], 2)
    assert restarts_seen("always", [0.6, 0.0, 0.6], start=4) == ([1, 1, 3], 2)
    at = config(policy_restarts=2, policy_restart_when="unsolved", policy_restart_from=5)
    assert [at.policy_restarts_at(n, False) for n in (2, 4, 5, 8)] == [1, 1, 2, 2]
    assert at.policy_restarts_at(6, True) == 1
    # a step widens the search in each further unsolved episode
    grows = config(policy_restarts=2, policy_restart_when="unsolved", policy_restart_from=5,
                   policy_restart_step=1)
    assert [grows.policy_restarts_at(n, False) for n in (4, 5, 6, 8)] == [1, 2, 3, 5]
    assert grows.policy_restarts_at(7, True) == 1
    with pytest.raises(ValueError, match="policy_restart_step must be a whole number >= 0"):
        config(policy_restart_step=-1)
    with pytest.raises(ValueError, match="policy_restart_from must be a whole number"):
        config(policy_restart_from=0)
    with pytest.raises(ValueError, match="policy_restart_when must be 'always' or 'unsolved'"):
        config(policy_restart_when="solved")


@pytest.mark.parametrize("when, gains, want", [
    ("always", [0.0, 0.6, 0.6], [1e-3, 1e-3, 1e-3]),
    ("solved", [0.0, 0.6, 0.6], [None, None, 1e-3]),  # solved in episode 3
    ("solved", [0.0, 0.0, 0.0], [None, None, None]),
])
def test_the_policy_early_stop_can_wait_for_a_solved_episode(tmp_path, when, gains, want):
    exp, agents = experiment(tmp_path, config(policy_early_stop=when,
                                              policy_min_rel_improvement=1e-3))
    exp.run_random_episode()
    for gain in gains:  # gain 0: the episode goes nowhere, unsolved
        agents[0].gain = gain
        exp.run_learned_episode()
    assert [c[2] for c in agents[0].calls if c[0] == "policy"] == want
    assert exp.config.policy_early_stop_at(False) == want[0]
    assert exp.config.policy_early_stop_at(True) == 1e-3
    assert config(policy_min_rel_improvement=None).policy_early_stop_at(True) is None


def test_policy_searches_can_start_fresh_until_an_episode_is_solved(tmp_path):
    class Controller:
        def __init__(self):
            self.seeds = []

        def randomize(self, seed=None):
            self.seeds.append(seed)

    def fresh_starts(when, gains):
        exp, agents = experiment(tmp_path / when, config(episodes=1 + len(gains),
                                                         policy_warm_start=when))
        exp.run_random_episode()
        agents[0].controller = Controller()
        for gain in gains:  # gain 0: the episode goes nowhere, unsolved
            agents[0].gain = gain
            exp.run_learned_episode()
        return agents[0].controller.seeds, exp.solved_at_episode()

    # the first learned episode (2) starts from the initial policy; 3 and 4 from fresh
    # ones, seeded by the episode; once episode 4 solved, 5 starts from 4's policy
    assert fresh_starts("solved", [0.0, 0.0, 0.6, 0.6]) == ([3003, 3004], 4)
    assert fresh_starts("always", [0.0, 0.0, 0.6, 0.6]) == ([], 4)
    exp, agents = experiment(tmp_path / "none", config(policy_warm_start="solved"))
    exp.run_random_episode()
    agents[0].controller = object()
    agents[0].gain = 0.0
    exp.run_learned_episode()  # the first learned episode needs no fresh policy
    with pytest.raises(TypeError, match="needs a controller with randomize"):
        exp.run_learned_episode()
    with pytest.raises(ValueError, match="policy_warm_start must be 'always' or 'solved'"):
        config(policy_warm_start="never")


def test_the_policy_search_hook_runs_before_each_policy_search(tmp_path):
    seen = []

    def hook(run, number):
        # the model of this episode is trained, its policy not yet optimised
        seen.append((number, [c[0] for c in run.agent.calls].count("policy")))

    exp, agents = experiment(tmp_path, before_policy_search=hook)
    exp.run()
    assert seen == [(2, 0), (3, 1), (4, 2)]


def test_the_reacher_paper_code_preset():
    from pilco.tasks import reacher
    from pilco.tasks.reacher import DAMAGED_REACHER, REACHER

    args = DAMAGED_REACHER.parse(["--preset", "paper-code", "--cost-width", "0.5"])
    assert (args.planning_horizon, args.start_var, args.policy_iters, args.policy_iters_first,
            args.max_data) == (100, 0.1, 30, 60, 100)
    assert args.cost_width == 0.5  # a flag given wins over the preset
    kw = reacher.env_kwargs(args, damaged=True)
    assert kw["joint_state"] == "commanded" and kw["damage_mode"] == "stuck"
    # the published damaged-arm script: 25 steps of up to 0.3 rad
    assert (args.horizon, args.max_action, kw["max_action"]) == (25, 0.3, 0.3)
    assert args.policy_min_rel_improvement == 0.0  # no early stop, as the script
    config = DAMAGED_REACHER.config(args)
    assert config.horizon == 25 and config.env_kwargs["max_episode_steps"] == 25
    paper = REACHER.parse(["--preset", "paper-code"])  # one cost, as the paper's code
    assert (paper.cost_width, paper.fine_cost_width, paper.limit_cost) == (1.0, 0.0, 0.0)
    assert (paper.horizon, paper.max_action) == (50, 0.1)  # the healthy script's
    healthy = REACHER.parse([])
    assert healthy.preset is None
    assert reacher.env_kwargs(healthy, False)["joint_state"] == "measured"


def test_success_when_the_last_episode_holds_the_target():
    """``solved_in_last_episode``: the pendulum's success, the hold rule on the last
    episode (a learned one) whatever happened before."""
    from pilco.experiment.scoring import solved_in_last_episode

    cfg = ExperimentConfig(task="t", env_id="x", episodes=3, solved_rule="hold", hold_steps=3,
                           success_threshold=0.3)
    success = solved_in_last_episode(cfg)
    held, dropped = [3.0, 1.0, 0.2, 0.1, 0.2], [3.0, 0.1, 0.1, 0.1, 0.5]

    def summary(*episodes):
        return {"episodes": [{"random": r} for r, _ in episodes],
                "distances": [d for _, d in episodes]}

    assert success(summary((True, dropped), (False, held)))
    assert not success(summary((False, held), (False, dropped)))  # up once, not at the end
    assert not success(summary((True, held)))  # a random episode does not count
    assert not success(summary((False, [3.0, 0.1, 0.1])))  # fewer steps than hold_steps
    assert not success(summary())


def test_held_for_good_needs_every_learned_episode_after_the_first_success():
    """``held_for_good``: the cart-pole's success, solved in a learned episode and in
    every learned one after it; ``solved_episodes`` lists the solved learned episodes."""
    from pilco.experiment.scoring import held_for_good, held_for_good_rule, solved_episodes

    cfg = ExperimentConfig(task="t", env_id="x", episodes=5, solved_rule="hold", hold_steps=2,
                           success_threshold=0.3)
    up, down = [3.0, 0.2, 0.1], [3.0, 0.1, 0.9]

    def run(*episodes):
        records = [{"episode": i + 1, "random": r} for i, (r, _) in enumerate(episodes)]
        return records, [d for _, d in episodes]

    assert held_for_good(*run((True, up), (False, down), (False, up), (False, up)), cfg)
    assert solved_episodes(*run((True, up), (False, down), (False, up), (False, up)),
                           cfg) == [3, 4]  # a random episode that holds does not count
    assert not held_for_good(*run((True, down), (False, up), (False, down), (False, up)), cfg)
    assert not held_for_good(*run((True, down), (False, up), (False, up), (False, down)), cfg)
    assert not held_for_good(*run((True, up), (False, down), (False, down)), cfg)
    assert not held_for_good(*run((True, up)), cfg)
    records, distances = run((True, down), (False, up), (False, up))
    assert held_for_good_rule(cfg)({"episodes": records, "distances": distances})


class MixtureAgent(StandInAgent):
    """A stand-in agent with a start mixture: its expected return is lower from the
    mixture (the policy is fragile) by ``gap``."""

    gap = 2.0

    def __init__(self, data, **kw):
        super().__init__(data, **kw)
        self.start_spread = None
        self.spreads = []  # the mixture each policy search ran with
        self.policy_evaluations = 0

    def optimize_policy(self, maxiter, restarts, seed, callback, method, min_rel_improvement,
                        patience):
        self.spreads.append(self.start_spread)
        self.policy_evaluations = 7 if self.start_spread is None else 3
        return super().optimize_policy(maxiter, restarts, seed, callback, method,
                                       min_rel_improvement, patience)

    def expected_return(self):
        return 1.0 - (self.gap if self.start_spread is not None else 0.0)


@pytest.mark.parametrize("gap, searched", [(2.0, True), (0.5, False)])
def test_a_fragile_policy_is_searched_again_on_the_start_mixture(tmp_path, gap, searched):
    MixtureAgent.gap = gap
    exp, agents = experiment(tmp_path, config(policy_start_mixture=1.5,
                                              policy_start_mixture_when="fragile"),
                             agent_class=MixtureAgent)
    exp.run_random_episode()
    agent = agents[0]
    agent.gain = 0.6
    first = exp.run_learned_episode()  # solves: nothing solved before it, no check
    assert agent.spreads == [None] and "start_mixture" not in first
    second = exp.run_learned_episode()  # solved before: the fragility check
    note = second["start_mixture"]
    assert note["plain_return"] == 1.0 and note["mixture_return"] == 1.0 - gap
    assert note["searched"] is searched
    assert agent.spreads == ([None, None, 1.5] if searched else [None, None])
    assert second["policy_evaluations"] == (7 + 3 if searched else 7)
    assert agent.start_spread is None  # the plain objective is left in place
    with pytest.raises(ValueError, match="policy_start_mixture_when"):
        config(policy_start_mixture_when="sometimes")


class WideStartAgent(StandInAgent):
    """A stand-in agent with start points and a wide start: records what each policy
    search ran with."""

    def __init__(self, data, **kw):
        super().__init__(data, **kw)
        self.S_init = np.array([[0.04]])
        self.start_points = None
        self.start_scale = None
        self.seen = []  # (start points, start scale) of each policy search

    def optimize_policy(self, maxiter, restarts, seed, callback, method, min_rel_improvement,
                        patience):
        self.seen.append((self.start_points, self.start_scale))
        return super().optimize_policy(maxiter, restarts, seed, callback, method,
                                       min_rel_improvement, patience)


@pytest.mark.parametrize("when", ["solved", "always"])
def test_start_points_and_wide_start_are_switched_on_once_solved(tmp_path, when):
    """The flank points, samples and wide start of the config reach the agent's policy
    searches from the first one after a solved episode (``"solved"``) or from the first
    (``"always"``); the samples are drawn again in every episode."""
    exp, agents = experiment(tmp_path, config(policy_flank_points=1.5,
                                              policy_start_samples=3, policy_start_scale=2.0,
                                              policy_start_points_when=when),
                             agent_class=WideStartAgent)
    exp.run_random_episode()
    agent = agents[0]
    agent.gain = 0.6
    exp.run_learned_episode()  # solves
    exp.run_learned_episode()
    exp.run_learned_episode()
    (p1, s1), (p2, s2), (p3, s3) = agent.seen
    if when == "solved":
        assert p1 is None and s1 is None
    else:
        assert p1.shape == (1, 2 + 3, 1) and s1 == 2.0
    assert s2 == s3 == 2.0
    assert p2.shape == p3.shape == (1, 2 + 3, 1)
    np.testing.assert_allclose(p2[0, :2, 0], [0.3, -0.3])  # 1.5 standard deviations out
    np.testing.assert_array_equal(p2[0, :2], p3[0, :2])  # the flank points stay
    assert not np.array_equal(p2[0, 2:], p3[0, 2:])  # the samples are drawn again


def test_a_watch_sees_the_states_and_its_pause_counts_as_policy_time(tmp_path):
    """The hooks' ``watch`` wraps the agent's policy for the episodes it chooses (here
    episode 2 only), sees every state as it comes, and the seconds it notes as a pause
    move from interaction to policy time."""
    import time

    seen = []

    def watch(run, number, policy):
        if number != 2:
            return policy

        def watched(x):
            seen.append(np.array(x))
            if len(seen) == 2:
                time.sleep(0.2)  # a pause, e.g. to re-plan
                exp.policy_notes["paused_seconds"] = 0.2
            return policy(x)

        return watched

    exp, agents = experiment(tmp_path, watch=watch)
    exp.run_random_episode()
    exp.run_learned_episode()
    episode = exp.episodes[-1]
    np.testing.assert_array_equal(np.array(seen), episode.states[:-1])
    assert exp.records[-1]["seconds"]["interaction"] == pytest.approx(episode.seconds - 0.2)
    assert exp.records[-1]["seconds"]["interaction"] < 0.2 <= exp.records[-1]["seconds"]["policy"]
    assert "paused_seconds" not in exp.records[-1]
    exp.run_learned_episode()  # no watch: the agent's own policy
    assert len(seen) == episode.steps


def last_real_return(exp, agent):
    """The last episode's real return on the agent's horizon, as the rule computes it."""
    last = exp.records[-1]
    return agent.horizon * (1.0 - last["cost"] / last["steps"])


class RepeatingAgent(StandInAgent):
    """A stand-in agent whose policy search reports per-run returns set by the test,
    relative to the last episode's real return (``offsets``), and records the run put in
    place."""

    offsets = (0.5, -3.0)

    def __init__(self, data, **kw):
        super().__init__(data, **kw)
        self.used = []
        self.policy_run_returns = []
        self.last_real = None

    def optimize_policy(self, maxiter, restarts, seed, callback, method, min_rel_improvement,
                        patience):
        super().optimize_policy(maxiter, restarts, seed, callback, method,
                                min_rel_improvement, patience)
        self.policy_run_returns = [self.last_real + o for o in self.offsets[:restarts]]
        return max(self.policy_run_returns)

    def use_policy_run(self, run):
        self.used.append(run)
        return self.policy_run_returns[run]


@pytest.mark.parametrize("offsets, leave, used", [
    ((0.5, -3.0), 1.0, [1]),     # the continued run wins but only repeats: the fresh one
    ((2.0, -3.0), 1.0, []),      # the continued run promises more than the last episode
    ((-0.5, -3.0), 1.0, [1]),    # ... or a little less: the same outcome
    ((-2.0, -3.0), 1.0, []),     # ... much less: the model does not reproduce the last one
    ((0.5, 1.0), 1.0, []),       # a fresh run wins anyway
    ((0.5, -3.0), None, []),     # off
])
def test_a_search_that_would_repeat_a_known_outcome_runs_a_fresh_policy(tmp_path, offsets,
                                                                        leave, used):
    """``policy_leave_repeat``: when the run continued from the last policy wins with a
    predicted return within the setting of the last episode's real return
    (``horizon * (1 - cost / steps)``), the best fresh run is put in place and noted."""
    RepeatingAgent.offsets = offsets
    exp, agents = experiment(tmp_path, config(policy_restarts=2, policy_leave_repeat=leave),
                             agent_class=RepeatingAgent)
    exp.run_random_episode()
    agent = agents[0]
    agent.last_real = last_real_return(exp, agent)
    record = exp.run_learned_episode()
    assert agent.policy_restarts == [2]
    assert agent.used == used
    if used:
        note = record["left_repeat"]
        assert note["fresh_run"] == 1
        assert np.isclose(note["continued_return"], agent.last_real + offsets[0])
        assert np.isclose(note["last_real_return"], agent.last_real)
        assert np.isclose(note["fresh_return"], agent.last_real + offsets[1])
    else:
        assert "left_repeat" not in record
    with pytest.raises(ValueError, match="policy_leave_repeat must be a number >= 0"):
        config(policy_leave_repeat=-1.0)


def test_a_solved_run_repeats_its_policy_even_when_the_model_knows_its_outcome(tmp_path):
    """The rule is for stuck runs: once an episode was solved, repeating its outcome is
    what is wanted, and the continued run's policy stays (restarts running or not)."""
    RepeatingAgent.offsets = (0.5, -3.0)
    exp, agents = experiment(tmp_path, config(policy_restarts=2, policy_leave_repeat=1.0),
                             agent_class=RepeatingAgent)
    exp.run_random_episode()
    agent = agents[0]
    agent.gain = 0.6  # the stand-in's policy solves the line task
    agent.last_real = last_real_return(exp, agent)
    exp.run_learned_episode()
    assert exp.solved_at_episode() == 2 and agent.used == [1]  # unsolved before it
    agent.last_real = last_real_return(exp, agent)
    record = exp.run_learned_episode()
    assert agent.policy_restarts == [2, 2] and agent.used == [1]
    assert "left_repeat" not in record


def test_the_loop_follows_the_hooks_schedule(tmp_path):
    """The episodes run while ``before_episode`` says so (here 3 of the config's 4), each
    followed by ``after_episode``, then ``finished`` once; ``opened`` comes first, and a
    run read back opens again and finishes without another episode."""
    calls = []

    def before(run, number):
        calls.append(("before", number, len(run.episodes)))
        return number <= 3

    exp, _ = experiment(tmp_path, opened=lambda run: calls.append(("opened",)),
                        before_episode=before,
                        after_episode=lambda run, n: calls.append(("after", n)),
                        finished=lambda run: calls.append(("finished", len(run.episodes))))
    summary = exp.run()
    assert calls == [("opened",), ("before", 1, 0), ("after", 1), ("before", 2, 1),
                     ("after", 2), ("before", 3, 2), ("after", 3), ("before", 4, 3),
                     ("finished", 3)]
    assert summary["complete"] and len(summary["episodes"]) == 3
    calls.clear()
    base, _ = experiment(tmp_path / "other")
    resumed = Experiment.resume(exp.directory, config(), LineHooks(
        base.hooks.build_agent, opened=lambda run: calls.append(("opened",)),
        before_episode=before, finished=lambda run: calls.append(("finished", 3))))
    assert resumed.run()["complete"] and len(resumed.episodes) == 3
    assert calls == [("opened",), ("before", 4, 3), ("finished", 3)]
    with pytest.raises(TypeError, match="hooks must be a pilco.experiment.RunHooks"):
        Experiment(config(), str(tmp_path / "bad"), base.hooks.build_agent)
