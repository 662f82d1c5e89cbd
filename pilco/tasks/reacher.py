"""The paper's 7-DoF Fetch joint-space reacher (paper §4, §5.1) and its damaged arm
(§5.2) as tasks.

Defaults are the paper's where it states them: 4 episodes of at most 50 steps (1 random
with actions uniform in ±0.05 rad, then 3 learned), an RBF policy of 50 basis functions
with sine squashing to ±0.1 rad, 10 independent dynamics GPs, an episode stops once the
gripper is within 5 cm of the target. "Success": the last episode reaches the target
within 15 steps.

The damaged arm is the paper's: the elbow's motor is unresponsive, the joint ignores
every command and stays at its start angle (``--damage-mode stuck``); the policy is not
told. ``--damage-mode straight`` forces the elbow to 0 rad instead, a harder variant
whose arm starts about 1.2 m from the target. Both arms share every default below.

One default differs from the paper: the GPs learn from every transition (at most 200 in
4 episodes), where the paper kept only the first 2T = 100 (``--max-data 100`` restores
that). With the cap the model never sees the last two episodes, so it knows nothing of
the region near the target unless episode 2 already got there.

Settings the paper leaves open (chosen here, every one a flag; the measurements behind
them are in ``docs/success-rates.md``):

- ``--cost-width`` σ_c = 0.2 m of the saturating cost ``1 - exp(-d² / (2 σ_c²))`` on the
  gripper position (``ExponentialReward`` with ``W = diag(1/σ_c², 1/σ_c², 1/σ_c², 0...)``),
  plus ``--fine-cost-width`` 0.05 m, a narrow second cost (``CombinedRewards``) that
  rewards precision near the target, where the failures were close misses and stalls.
- ``--limit-cost`` 0.1 rad: saturating bumps of this width at the joint limits are
  subtracted from the reward (weight ``--limit-cost-weight`` 0.5 each), so that the
  policy keeps the predicted joints off their limits, where the real joint stops but
  the model, which has rarely seen it there, predicts it moving on. ``0`` turns it off.
- ``--start-var`` 1e-4: the initial state distribution is N(start observation, 1e-4·I);
  in the first learned episode (``--early-episodes`` 1) it is ``--early-start-var`` 0.1·I
  (the paper code's ``S_init``, for that episode only): a policy optimised for a wide
  start distribution brings the arm near the target sooner, and the episodes after it
  give the model data there. ``--early-cost-width`` likewise widens the main cost in
  those episodes (off by default).
- ``--policy-init-var`` 0.1: the initial policy's 50 RBF centres are drawn from
  N(start observation, 0.1·I), targets from N(0, 0.1²), as the MATLAB release
  initialises its policies (:func:`init_policy_near`); 0 draws the centres from
  N(0, I), which puts most of them far from the arm's states (its joint angles start at
  -1 and 2 rad).
- ``--policy-iters`` 25 and ``--model-iters`` 100 L-BFGS iterations, 1 restart each; a
  policy search stops once its predicted return grew by less than 1 % over 5 iterations
  (``--policy-min-rel-improvement`` 0.01, ``--policy-patience`` 5; 0 turns it off):
  the later iterations polish a policy that already reaches.
- GP-input columns that are constant in the data (a damaged joint's measured angle) get
  a long lengthscale after every model fit (:func:`ignore_constant_inputs`).
- ``--gp-priors none``: maximum evidence; ``paper`` puts the paper code's Gamma priors
  on the GPs' lengthscales and signal variances (:data:`PAPER_GP_PRIORS`).

``--preset paper-code`` starts from the published scripts' settings
(:data:`PAPER_CODE`: planning horizon 100, ``S_init = 0.1 I``, one cost of width 1 m,
30 policy iterations (60 the first time, no early stop), the first 100 transitions,
commanded joint angles in the state, the GP priors); the damaged arm's script also
kept the elbow stuck and ran episodes of 25 steps of up to 0.3 rad
(:data:`PAPER_CODE_DAMAGED`).

``--target-spread S`` draws the target uniformly in the cube of half-width ``S`` [m]
around ``--target`` (default the env's (1.2, 0.38, 0.38)) from the run's seed
(:func:`draw_target`), so that a sweep over seeds also varies the target.

Frames of the final episode are rendered by replaying its joint angles in another
process (MuJoCo's EGL renderer and TensorFlow cannot share a process).
"""
from __future__ import annotations

import logging
from typing import Any, Dict, List, Optional, Sequence

import numpy as np

from ..envs.fetch_damage import DAMAGE_MODES
from ..experiment import Experiment, ExperimentConfig, make_env
from .base import Task, TaskHooks
from .reacher_agent import after_model_fit, agent_builder, schedule, set_gp_priors
from .settings import (RunSettings, non_negative_float, positive_float, positive_int, setting,
                       task_settings)

__all__ = ["ReacherSettings", "DamagedReacherSettings", "ReacherTask", "ReacherHooks", "REACHER",
           "DAMAGED_REACHER", "env_kwargs", "reached_within", "SUCCESS_STEPS", "draw_target",
           "check_drawn_target", "PAPER_CODE", "PAPER_CODE_DAMAGED", "LEARNED_EPISODES"]


#: Paper figures of the reacher (its own machine, with a GPU).
PAPER_SECONDS = {"interaction": 21.22, "model": 37.53, "policy": 1380.95, "total": 1598.0}

#: The paper's published scripts, as far as this library reproduces them (the policy's
#: trainable noise variance is not reproduced).
PAPER_CODE = dict(planning_horizon=100, start_var=0.1, cost_width=1.0, fine_cost_width=0.0,
                  limit_cost=0.0, policy_iters=30, policy_iters_first=60, max_data=100,
                  joint_state="commanded", gp_priors="paper", early_start_var=0.0,
                  policy_init_var=0.0, policy_min_rel_improvement=0.0)

#: What the published damaged-arm script changed on top of :data:`PAPER_CODE`: the elbow
#: stuck at its start angle, episodes of 25 steps, steps of up to 0.3 rad.
PAPER_CODE_DAMAGED = dict(damage_mode="stuck", horizon=25, max_action=0.3)

logger = logging.getLogger(__name__)

#: mixed with the run's seed into the generator of :func:`draw_target`, so that the
#: target's draw is independent of the run's other draws of the same seed
TARGET_STREAM = 3

#: success: the last episode reaches the target within this many steps
SUCCESS_STEPS = 15

#: the reacher's learned episodes (its --episodes minus --random-episodes); the
#: adaptation's healthy arm gets the same budget
LEARNED_EPISODES = 3


@task_settings(episodes=1 + LEARNED_EPISODES, horizon=50, basis_functions=50, policy_iters=25,
               model_iters=100, policy_min_rel_improvement=0.01, policy_patience=5,
               output="runs/reacher-seed{seed}")
class ReacherSettings(RunSettings):
    """The reacher's settings (the damaged arm and the adaptation start from these)."""

    cost_width: float = setting(0.2, "σ_c [m] of the saturating cost on the gripper-target "
                                "distance", kind=positive_float)
    fine_cost_width: float = setting(
        0.05, "add a second, narrow saturating cost of this width [m] (more precision near "
        "the target; 0: none)", kind=non_negative_float)
    limit_cost: float = setting(
        0.1, "penalise predicted joint angles near their limits: a saturating bump of this "
        "width [rad] at each limit of the limited joints (0: none)", kind=non_negative_float,
        metavar="WIDTH")
    limit_cost_weight: float = setting(
        0.5, "weight of each joint-limit bump against the position cost",
        kind=non_negative_float)
    early_cost_width: float = setting(
        0.0, "width [m] of the main cost in the first --early-episodes learned episodes "
        "(then --cost-width again; 0: no schedule)", kind=non_negative_float)
    early_start_var: float = setting(
        0.1, "variance of the initial state distribution in the first --early-episodes "
        "learned episodes (then --start-var; 0: no schedule)", kind=non_negative_float)
    early_episodes: int = setting(
        1, "learned episodes that use --early-cost-width / --early-start-var",
        kind=positive_int)
    policy_init_var: float = setting(
        0.1, "draw the initial policy's RBF centres from N(start observation, this·I), as "
        "the MATLAB release does (0: from N(0, I))", kind=non_negative_float)
    gp_priors: str = setting(
        "none", "priors on the dynamics GPs' hyperparameters: 'paper' the paper code's Gamma "
        "priors on lengthscales and signal variance (MAP)", choices=("none", "paper"))
    planning_horizon: Optional[int] = setting(
        None, "steps the policy is optimised over", kind=positive_int, unset="--horizon")
    start_var: float = setting(1e-4, "variance of the initial state distribution (times the "
                               "identity)", kind=positive_float)
    random_action: float = setting(0.05, "random episodes: actions uniform in ±this [rad]",
                                   kind=positive_float)
    max_action: float = setting(0.1, "policy and env bound of the per-step joint rotation "
                                "[rad]", kind=positive_float)
    threshold: float = setting(0.05, "success distance [m]; episodes stop there",
                               kind=non_negative_float)
    no_early_stop: bool = setting(False, "run every episode for the full horizon even at the "
                                  "target")
    target: Optional[tuple] = setting(
        None, "target position [m]", kind=float, nargs=3, metavar=("X", "Y", "Z"),
        unset="the env's (1.2, 0.38, 0.38)")
    target_spread: float = setting(
        0.0, "draw the target uniformly within ±S m per axis of --target (or of the default "
        "target) from the run's seed; 0: no draw", kind=non_negative_float, metavar="S")
    start_noise: float = setting(0.0, "std [rad] of noise on the start joint angles",
                                 kind=non_negative_float)
    damage_mode: str = setting(
        "stuck", "damaged arm: the joints ignore commands and stay at their start angle "
        "('stuck', the paper's damage) or are forced to 0 rad ('straight': the elbow "
        "straightened, a harder variant that needs at least 13 steps to the paper's "
        "target)", choices=DAMAGE_MODES)
    joint_state: str = setting(
        "measured", "the state's joint angles: measured, or commanded (the running sum of "
        "the actions, as the paper's code)", choices=("measured", "commanded"))
    damaged_joints: tuple = setting(("elbow_flex",), "damaged arm: joints that ignore "
                                    "commands", kind=str, nargs="+")
    constant_input_lengthscale: float = setting(
        100.0, "lengthscale given to GP inputs that are constant in the data (a damaged "
        "joint) after every model fit; 0: leave them to training", kind=non_negative_float)
    render_size: tuple = setting((320, 240), "frame size of the rendered final episode",
                                 kind=positive_int, nargs=2, metavar=("W", "H"))


#: values that runs saved by earlier versions may hold, read as today's (the straightened
#: arm's earlier name; the adaptation's "no fine cost" saved as null)
ReacherSettings.EARLIER_VALUES = {"damage_mode": {"zero": "straight"},
                                  "fine_cost_width": {None: 0.0}}


@task_settings(output="runs/damaged-reacher-seed{seed}")
class DamagedReacherSettings(ReacherSettings):
    """The damaged arm's settings: the healthy arm's defaults (with the paper's damage,
    the elbow stuck at its start angle, it starts in the same pose)."""


def env_kwargs(s: ReacherSettings, damaged: bool) -> Dict[str, Any]:
    """Keyword arguments of ``FetchJointReacher`` for the settings ``s``."""
    kw = dict(max_action=s.max_action, distance_threshold=s.threshold,
              joint_state=s.joint_state, start_noise=s.start_noise,
              render_width=s.render_size[0], render_height=s.render_size[1])
    if s.target_spread > 0:
        kw["target"] = tuple(draw_target(s.seed, s.target_spread, s.target))
    elif s.target is not None:
        kw["target"] = tuple(s.target)
    if damaged:
        kw.update(damaged_joints=tuple(s.damaged_joints), damage_mode=s.damage_mode)
    if s.no_early_stop:
        kw["distance_threshold"] = 0.0  # the env never terminates; success still counted
    return kw


def draw_target(seed: int, spread: float, around: Optional[Sequence[float]] = None
                ) -> np.ndarray:
    """A target [3] drawn uniformly within ±``spread`` m per axis of ``around`` (default
    the env's default target), from a generator of ``(TARGET_STREAM, seed)``: the same
    seed gives the same target. Whether the arm can reach it within the success rule:
    :func:`pilco.envs.fewest_steps`."""
    from ..envs.fetch_reacher import DEFAULT_TARGET

    centre = np.asarray(DEFAULT_TARGET if around is None else around, dtype=np.float64)
    rng = np.random.default_rng([TARGET_STREAM, int(seed)])
    return centre + rng.uniform(-spread, spread, size=3)


def check_drawn_target(env) -> None:
    """Log a drawn target and the fewest steps that reach it; warn when the success
    rule's steps cannot (the run goes on: its rate then says so)."""
    from ..envs import fewest_steps

    target = np.round(env.unwrapped.target, 4).tolist()
    try:
        steps = fewest_steps(env, starts=16).steps
    except ValueError:
        steps = None
    if steps is None or steps > SUCCESS_STEPS:
        logger.warning("drawn target %s: the arm needs %s steps at least, the success "
                       "rule allows %d", target, "more than any search found" if steps is None
                       else steps, SUCCESS_STEPS)
    else:
        logger.info("drawn target %s: reachable in %d steps at least", target, steps)


def reached_within(steps: int):
    """``summary -> bool``: the last episode reached the target within ``steps`` steps."""

    def success(summary: Dict[str, Any]) -> bool:
        last = summary["episodes"][-1] if summary["episodes"] else None
        return bool(last is not None and not last["random"]
                    and last["steps_to_target"] is not None
                    and last["steps_to_target"] <= steps)

    return success


class ReacherHooks(TaskHooks):
    """The reacher's run: the frames replayed in another process, the constant inputs'
    lengthscales after every model fit, the cost width and start variance of the
    episode's schedule, reached within :data:`SUCCESS_STEPS` steps."""

    draws_frames = True

    def __init__(self, task, s: ReacherSettings, config: ExperimentConfig, env):
        super().__init__(task, s, config, env)
        self._adjust, self._schedule = after_model_fit(s), schedule(s)

    def opened(self, run) -> None:
        if run.agent is not None:  # resumed from agent.npz, which holds no priors
            set_gp_priors(run.agent, self.settings)

    def render(self, run, episode):
        """The final episode's frames, replayed from its joint angles in another process
        (MuJoCo's EGL renderer and TensorFlow cannot share a process), with the target of
        the episode just run."""
        from ..envs.fetch_render import replay_fetch_frames

        return replay_fetch_frames(episode.states[:, 3:10], self.env.unwrapped.target,
                                   *self.settings.render_size)

    def after_model_fit(self, run, number: int) -> None:
        self._adjust(run.agent)

    def before_policy_search(self, run, number: int) -> None:
        self._schedule(run.agent, number)

    def success(self, summary: Dict[str, Any]) -> bool:
        return reached_within(SUCCESS_STEPS)(summary)


class ReacherTask(Task):
    """The Fetch joint-space reacher (``damaged``: with the paper's damaged arm)."""

    name = "reacher"
    settings = ReacherSettings
    description = "PILCO on the Fetch joint-space reacher"
    presets = {"paper-code": PAPER_CODE}
    paper_seconds = PAPER_SECONDS
    damaged = False

    def config(self, s: ReacherSettings) -> ExperimentConfig:
        from ..envs import FETCH_DAMAGED_ID, FETCH_ID

        return self.loop_config(
            s, env_id=FETCH_DAMAGED_ID if self.damaged else FETCH_ID,
            env_kwargs={**env_kwargs(s, self.damaged), "max_episode_steps": s.horizon},
            random_action_scale=s.random_action, cost_width=s.cost_width,
            success_threshold=s.threshold, solved_rule="reach")

    def make_env(self, s: ReacherSettings, config: ExperimentConfig):
        """The arm (the reward needs its target, so it is made before the agent); a drawn
        target is logged with the fewest steps that reach it."""
        env = make_env(config.env_id, config.env_kwargs, render=False)
        if s.target_spread > 0:
            check_drawn_target(env)
        return env

    def agent_builder(self, s: ReacherSettings, env):
        return agent_builder(s, env.unwrapped.target, env.unwrapped.joint_limits)

    run_hooks = ReacherHooks

    def figures(self, exp: Experiment, s: ReacherSettings) -> List[str]:
        """Distances, predicted vs real cost, one- and multi-step predictions, the final
        episode as a GIF."""
        from .. import plotting

        return plotting.save_all(exp, exp.directory, title=self.name.replace("_", " "),
                                 state_dims=(0, 1, 2), state_names=("x", "y", "z"),
                                 distance_label="distance to target [m]",
                                 threshold=exp.config.success_threshold)


class DamagedReacherTask(ReacherTask):
    """The reacher on the paper's damaged arm: the elbow ignores every command."""

    name = "damaged_reacher"
    settings = DamagedReacherSettings
    description = "PILCO on the Fetch joint-space reacher with a damaged joint"
    presets = {"paper-code": dict(PAPER_CODE, **PAPER_CODE_DAMAGED)}
    damaged = True


REACHER = ReacherTask()
DAMAGED_REACHER = DamagedReacherTask()
