"""Multi-task PILCO on the Fetch reacher: one policy that reaches any target in a cube.

The state is the reacher's (gripper position, seven joint angles) plus the target, held
in three *context* dimensions (:class:`~pilco.envs.TargetInState`): constant through an
episode, read by the policy, never predicted by the dynamics GPs, which learn the arm
alone (:class:`~pilco.models.PILCO`'s ``context_indices``). ``--training-targets`` T
targets are drawn uniformly in the cube of half-width ``--target-cube`` around
``--target`` (default the paper's (1.2, 0.38, 0.38)); episode k runs on training target
``(k - 1) mod T`` (the random first episode on the first one), so ``--episodes`` 12 is
three rounds of four targets. The policy objective is the sum of the T targets' expected
returns, each from its own start distribution (the arm's start, the target as context),
with the saturating costs on the gripper position minus the target
(:class:`~pilco.rewards.LinearMapReward`). Each start distribution gives the target a
variance (``--context-var``, default 0.005 m², a standard deviation of 7 cm): the policy
is then optimised for targets around each training target as well, which carries it to
targets between them.

After the last episode the policy runs, without learning, on ``--test-targets`` targets
drawn from another stream in the same cube (held out: never trained on); the summary
holds each one's steps to 5 cm (``test_steps``, null when not within the horizon) and
``test_reached``, the number reached within :data:`~pilco.tasks.reacher.SUCCESS_STEPS`
steps. "Success": at least :data:`SUCCESS_SHARE` of the test targets reached so.
"""
from __future__ import annotations

import logging
import math
from typing import Any, Dict, List, Optional

import numpy as np

from ..experiment import Experiment, ExperimentConfig, make_env
from ..experiment.episode import rollout
from . import reacher
from .reacher_agent import position_weights, reacher_agent
from .settings import non_negative_float, positive_int, setting, task_settings

__all__ = ["MultiReacherSettings", "MultiReacherTask", "MultiReacherHooks", "REACHER_MULTI",
           "draw_targets", "SUCCESS_SHARE", "CONTEXT"]

logger = logging.getLogger(__name__)

#: success: this share of the test targets reached within the success rule's steps
SUCCESS_SHARE = 0.9

#: the context dimensions of the state: the target's x, y, z
CONTEXT = (10, 11, 12)

#: the generators of the training and the test targets, mixed with the run's seed
TRAIN_STREAM, TEST_STREAM = 5, 6


@task_settings(episodes=12, planning_horizon=30, output="runs/reacher-multi-seed{seed}")
class MultiReacherSettings(reacher.ReacherSettings):
    """The multi-task reacher's settings: the reacher's, the targets and their cube."""

    training_targets: int = setting(4, "targets the policy is trained on (one episode each "
                                    "per round)", kind=positive_int, group="multi-task")
    test_targets: int = setting(20, "held-out targets the final policy is tested on",
                                kind=positive_int, group="multi-task")
    target_cube: float = setting(0.15, "half-width [m] of the cube around --target that "
                                 "the training and test targets are drawn from",
                                 kind=non_negative_float, group="multi-task")
    # the policy is optimised for targets spread around each training target, not only at
    # the training targets themselves, so that it also reaches the targets between them
    context_var: float = setting(0.005, "variance of the target in each training start "
                                 "distribution [m²] (spreads the objective over the cube "
                                 "between the training targets)", kind=non_negative_float,
                                 group="multi-task")


def draw_targets(seed: int, count: int, cube: float, around, stream: int) -> np.ndarray:
    """``count`` targets [count, 3] uniform in the cube of half-width ``cube`` around
    ``around`` [3], from a generator of ``(stream, seed)``."""
    rng = np.random.default_rng([stream, int(seed)])
    return np.asarray(around, dtype=np.float64) + rng.uniform(-cube, cube, size=(count, 3))


class MultiReacherHooks(reacher.ReacherHooks):
    """The multi-target run: each episode's training target (its reset options), the
    multi-target start-variance schedule, the summary's targets and the test of the final
    policy on the held-out ones once the run is complete; success as many of them reached
    as :data:`SUCCESS_SHARE` asks."""

    def __init__(self, task: "MultiReacherTask", s: MultiReacherSettings,
                 config: ExperimentConfig, env):
        super().__init__(task, s, config, env)
        self._schedule = schedule(s)
        self.train = task.targets(s, TRAIN_STREAM, s.training_targets)
        self.test_targets = task.targets(s, TEST_STREAM, s.test_targets)

    def opened(self, run) -> None:
        super().opened(run)
        run.summary_fields = {
            "training_targets": self.train.tolist(), "test_targets": self.test_targets.tolist(),
            "test_steps": None, "test_reached": None, **run.summary_fields}

    def reset_options(self, number: int) -> Optional[dict]:
        return {"target": self.train[(number - 1) % len(self.train)]}

    def finished(self, run) -> None:
        """The test of the final policy on the held-out targets (once per run)."""
        if run.summary_fields.get("test_steps") is None:
            self.test(run)
            run.save_progress()

    def test(self, run) -> List[Optional[int]]:
        """Run the agent's policy on every test target from the arm's start (seeds
        beyond the run's episodes'); the steps to the target (None: not reached)."""
        s, env, agent = self.settings, run.make_env(), run.agent
        steps: List[Optional[int]] = []
        for k, target in enumerate(run.summary_fields["test_targets"]):
            episode = rollout(env, lambda x: agent.compute_action(x)[0], s.horizon,
                              seed=run.episode_seed(s.episodes + 1 + k),
                              reset_options={"target": np.asarray(target)},
                              distance_fn=self.distance, quiet=True)
            near = np.flatnonzero(episode.distances <= s.threshold)
            steps.append(int(near[0]) if len(near) else None)
        reached = sum(n is not None and n <= reacher.SUCCESS_STEPS for n in steps)
        run.summary_fields.update(test_steps=steps, test_reached=int(reached))
        logger.info("held-out targets reached within %d steps: %d of %d",
                    reacher.SUCCESS_STEPS, reached, len(steps))
        return steps

    def success(self, summary: Dict[str, Any]) -> bool:
        reached = summary.get("test_reached")
        return reached is not None and reached >= math.ceil(
            SUCCESS_SHARE * self.settings.test_targets)


class MultiReacherTask(reacher.ReacherTask):
    """One policy for every target in a cube, trained on a few of them."""

    name = "reacher_multi"
    settings = MultiReacherSettings
    description = "Multi-task PILCO on the Fetch reacher: one policy for any target"
    presets: Dict[str, Dict[str, Any]] = {}
    paper_seconds = None

    def targets(self, s: MultiReacherSettings, stream: int, count: int) -> np.ndarray:
        from ..envs.fetch_reacher import DEFAULT_TARGET

        around = DEFAULT_TARGET if s.target is None else s.target
        return draw_targets(s.seed, count, s.target_cube, around, stream)

    def make_env(self, s: MultiReacherSettings, config: ExperimentConfig):
        from ..envs import TargetInState

        return TargetInState(make_env(config.env_id, config.env_kwargs, render=False))

    def agent_builder(self, s: MultiReacherSettings, env):
        """``(data, start_states) -> PILCO`` on the 13-dimensional state: an RBF policy
        reading all of it, GPs on the arm's ten dimensions, the costs on the gripper
        minus the target, one start per training target."""
        from ..rewards import ExponentialReward, LinearMapReward, difference_map

        train = self.targets(s, TRAIN_STREAM, s.training_targets)
        joint_limits = env.unwrapped.joint_limits

        def position_cost(D: int, width: float):
            A = difference_map(D, [0, 1, 2], list(CONTEXT))
            return LinearMapReward(D, ExponentialReward(3, position_weights(3, width),
                                                        np.zeros((1, 3))), A)

        def build(data, start_states):
            D = np.shape(data[1])[1]
            starts = np.repeat(start_states[0:1], len(train), axis=0)
            starts[:, list(CONTEXT)] = train
            return reacher_agent(s, data, start_states, joint_limits, position_cost,
                                 m_init=starts, S_init=start_cov(D, s.start_var, s.context_var),
                                 context_indices=CONTEXT)

        return build

    run_hooks = MultiReacherHooks

    def notes(self, summary: Dict[str, Any]) -> List[str]:
        return [f"\nheld-out targets reached within {reacher.SUCCESS_STEPS} steps: "
                f"{summary.get('test_reached')} of {len(summary.get('test_targets') or [])} "
                f"after {len(summary['episodes'])} episodes on "
                f"{len(summary.get('training_targets') or [])} training targets"]

    def figures(self, exp: Experiment, s: MultiReacherSettings) -> List[str]:
        """The reacher's figures and ``targets.png``: the training and test targets, each
        test target coloured by the steps the final policy took to it."""
        from .. import plotting

        fields = exp.summary_fields
        paths = super().figures(exp, s)
        if fields.get("test_steps") is not None:
            paths.append(plotting.plot_targets(
                fields["training_targets"], fields["test_targets"], fields["test_steps"],
                exp.directory + "/targets.png", within=reacher.SUCCESS_STEPS))
        return paths


def start_cov(D: int, var: float, context_var: float) -> np.ndarray:
    """The start covariance [D, D]: ``var`` on the arm's dimensions, ``context_var`` on the
    target's (at least 1e-12: a Gaussian needs a positive variance)."""
    diag = np.full(D, float(var))
    diag[list(CONTEXT)] = max(float(context_var), 1e-12)
    return np.diag(diag)


def schedule(s: MultiReacherSettings):
    """``(agent, episode number) -> None``: the reacher's start-variance schedule
    (``--early-start-var`` in the first ``--early-episodes`` learned episodes) on the
    arm's dimensions; the target's variance stays ``--context-var``."""

    def before_policy_search(agent, number: int) -> None:
        early = number - s.random_episodes <= s.early_episodes
        var = s.early_start_var if (early and s.early_start_var) else s.start_var
        agent.S_init = start_cov(agent.state_dim, var, s.context_var)

    return before_policy_search


REACHER_MULTI = MultiReacherTask()
