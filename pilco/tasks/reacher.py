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

import argparse
import logging
from typing import Any, Dict, List, Optional, Sequence

import numpy as np

from ..envs.fetch_damage import DAMAGE_MODES
from ..experiment import Experiment, ExperimentConfig, make_env
from ..experiment.cli import (add_common_arguments, add_preset_argument, finish,
                              learning_settings, non_negative_float, open_experiment,
                              parse_task_args, positive_float, positive_int)

__all__ = ["build_parser", "env_kwargs", "make_config", "agent_builder",
           "ignore_constant_inputs", "limit_bumps", "set_gp_priors", "make_experiment", "figures",
           "reached_within", "parse_args", "main", "SUCCESS_STEPS", "position_weights",
           "draw_target", "check_drawn_target",
           "main_position_reward", "schedule", "init_policy_near", "ADDED_LATER",
           "PAPER_CODE", "PAPER_CODE_DAMAGED"]


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

#: The paper code's priors on every dynamics GP's hyperparameters (GPflow 1's Gamma(shape,
#: scale)): lengthscales ~ Gamma(1, 10), signal variance ~ Gamma(1.5, 2); training is then
#: MAP instead of maximum evidence.
PAPER_GP_PRIORS = {"lengthscales": (1.0, 10.0), "variance": (1.5, 2.0)}

#: Settings added after runs were saved, with the value that reproduces such a run on
#: ``--resume`` (they ran without the fine and joint-limit costs and the schedule, with
#: policy centres from N(0, I)).
ADDED_LATER = dict(fine_cost_width=0.0, limit_cost=0.0, early_cost_width=0.0,
                   early_start_var=0.0, gp_priors="none", policy_init_var=0.0,
                   target_spread=0.0)

logger = logging.getLogger(__name__)

#: mixed with the run's seed into the generator of :func:`draw_target`, so that the
#: target's draw is independent of the run's other draws of the same seed
TARGET_STREAM = 3

#: success: the last episode reaches the target within this many steps
SUCCESS_STEPS = 15


def build_parser(damaged: bool = False) -> argparse.ArgumentParser:
    """Every flag of the (damaged) reacher task. The damaged arm has the healthy arm's
    defaults: with the paper's damage (the elbow stuck at its start angle) it starts in
    the same pose and reaches with the other six joints."""
    name = "damaged-reacher" if damaged else "reacher"
    parser = argparse.ArgumentParser(
        description=("PILCO on the Fetch joint-space reacher"
                     + (" with a damaged joint" if damaged else "")),
        formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    add_common_arguments(parser, episodes=4, steps=50, basis_functions=50, policy_iters=25,
                         model_iters=100, policy_restarts=1, model_restarts=1, max_data=None,
                         policy_min_rel_improvement=0.01, policy_patience=5,
                         output=f"runs/{name}-seed{{seed}}")
    presets = {"paper-code": dict(PAPER_CODE, **(PAPER_CODE_DAMAGED if damaged else {}))}
    g = parser.add_argument_group("reacher")
    g.add_argument("--cost-width", type=positive_float, default=0.2,
                   help="σ_c [m] of the saturating cost on the gripper-target distance")
    g.add_argument("--fine-cost-width", type=non_negative_float, default=0.05,
                   help="add a second, narrow saturating cost of this width [m] (more "
                        "precision near the target; 0: none)")
    g.add_argument("--limit-cost", type=non_negative_float, default=0.1, metavar="WIDTH",
                   help="penalise predicted joint angles near their limits: a saturating "
                        "bump of this width [rad] at each limit of the limited joints "
                        "(0: none)")
    g.add_argument("--limit-cost-weight", type=non_negative_float, default=0.5,
                   help="weight of each joint-limit bump against the position cost")
    g.add_argument("--early-cost-width", type=non_negative_float, default=0.0,
                   help="width [m] of the main cost in the first --early-episodes learned "
                        "episodes (then --cost-width again; 0: no schedule)")
    g.add_argument("--early-start-var", type=non_negative_float, default=0.1,
                   help="variance of the initial state distribution in the first "
                        "--early-episodes learned episodes (then --start-var; 0: no schedule)")
    g.add_argument("--early-episodes", type=positive_int, default=1,
                   help="learned episodes that use --early-cost-width / --early-start-var")
    g.add_argument("--policy-init-var", type=non_negative_float, default=0.1,
                   help="draw the initial policy's RBF centres from N(start observation, "
                        "this·I), as the MATLAB release does (0: from N(0, I))")
    g.add_argument("--gp-priors", choices=("none", "paper"), default="none",
                   help="priors on the dynamics GPs' hyperparameters: 'paper' the paper "
                        "code's Gamma priors on lengthscales and signal variance (MAP)")
    g.add_argument("--planning-horizon", type=positive_int, default=None,
                   help="steps the policy is optimised over (default: --horizon)")
    g.add_argument("--start-var", type=positive_float, default=1e-4,
                   help="variance of the initial state distribution (times the identity)")
    g.add_argument("--random-action", type=positive_float, default=0.05,
                   help="random episodes: actions uniform in ±this [rad]")
    g.add_argument("--max-action", type=positive_float, default=0.1,
                   help="policy and env bound of the per-step joint rotation [rad]")
    g.add_argument("--threshold", type=non_negative_float, default=0.05,
                   help="success distance [m]; episodes stop there")
    g.add_argument("--no-early-stop", action="store_true",
                   help="run every episode for the full horizon even at the target")
    g.add_argument("--target", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"),
                   help="target position [m] (default the env's (1.2, 0.38, 0.38))")
    g.add_argument("--target-spread", type=non_negative_float, default=0.0, metavar="S",
                   help="draw the target uniformly within ±S m per axis of --target (or of "
                        "the default target) from the run's seed; 0: no draw")
    g.add_argument("--start-noise", type=non_negative_float, default=0.0,
                   help="std [rad] of noise on the start joint angles")
    g.add_argument("--damage-mode", choices=DAMAGE_MODES, default="stuck",
                   help="damaged arm: the joints ignore commands and stay at their start "
                        "angle ('stuck', the paper's damage) or are forced to 0 rad "
                        "('straight': the elbow straightened, a harder variant that needs "
                        "at least 13 steps to the paper's target)")
    g.add_argument("--joint-state", choices=("measured", "commanded"), default="measured",
                   help="the state's joint angles: measured, or commanded (the running sum "
                        "of the actions, as the paper's code)")
    g.add_argument("--damaged-joints", nargs="+", default=["elbow_flex"],
                   help="damaged arm: joints that ignore commands")
    g.add_argument("--constant-input-lengthscale", type=non_negative_float, default=100.0,
                   help="lengthscale given to GP inputs that are constant in the data (a "
                        "damaged joint) after every model fit; 0: leave them to training")
    g.add_argument("--render-size", type=positive_int, nargs=2, default=[320, 240],
                   metavar=("W", "H"), help="frame size of the rendered final episode")
    add_preset_argument(parser, presets)
    return parser


def env_kwargs(args: argparse.Namespace, damaged: bool) -> Dict[str, Any]:
    """Keyword arguments of ``FetchJointReacher`` for the parsed ``args``."""
    kw = dict(max_action=args.max_action, distance_threshold=args.threshold,
              joint_state=getattr(args, "joint_state", "measured"),
              start_noise=args.start_noise, render_width=args.render_size[0],
              render_height=args.render_size[1])
    if args.target_spread > 0:
        kw["target"] = tuple(draw_target(args.seed, args.target_spread, args.target))
    elif args.target is not None:
        kw["target"] = tuple(args.target)
    if damaged:
        kw.update(damaged_joints=tuple(args.damaged_joints), damage_mode=args.damage_mode)
    if args.no_early_stop:
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


def make_config(args: argparse.Namespace, task: str, damaged: bool) -> ExperimentConfig:
    """The run's settings from the parsed flags."""
    from ..envs import FETCH_DAMAGED_ID, FETCH_ID

    return ExperimentConfig(
        task=task, env_id=FETCH_DAMAGED_ID if damaged else FETCH_ID, seed=args.seed,
        episodes=args.episodes, random_episodes=args.random_episodes, steps=args.horizon,
        env_kwargs={**env_kwargs(args, damaged), "max_episode_steps": args.horizon},
        random_action_scale=args.random_action, **learning_settings(args),
        cost_width=args.cost_width, success_threshold=args.threshold, solved_rule="reach",
        render=not args.no_render, predictions=not args.no_figures, quiet=args.quiet,
    )


def ignore_constant_inputs(agent, lengthscale: float = 100.0) -> None:
    """Give the dynamics GPs a long lengthscale on GP-input columns that are constant in
    the training data (a damaged joint held at one angle), so that the column is
    irrelevant; called after building the agent and after every model fit."""
    X = np.asarray(agent.mgpr.X)
    constant = np.std(X, axis=0) < 1e-9
    if not np.any(constant):
        return
    for model in agent.mgpr.models:
        ell = np.array(model.kernel.lengthscales.numpy(), dtype=float)
        ell[constant] = lengthscale
        model.kernel.lengthscales.assign(ell)


def agent_builder(args: argparse.Namespace, target: np.ndarray,
                  joint_limits: Optional[np.ndarray] = None):
    """``(data, start_states) -> PILCO`` for the reacher; ``target [3]`` is the gripper
    target, the reward looks at state dims 0..2 (x, y, z); with ``--limit-cost`` also at
    the joint angles (dims 3..9) near ``joint_limits [7, 2]`` (±inf: unlimited)."""
    from ..controllers import RbfController, squash_sin
    from ..models import PILCO
    from ..rewards import CombinedRewards, ExponentialReward

    def position_reward(D: int, width: float) -> ExponentialReward:
        t = np.zeros((1, D))
        t[0, :3] = target
        return ExponentialReward(D, position_weights(D, width), t)

    def build(data, start_states):
        X, Y = data
        D, U = Y.shape[1], X.shape[1] - Y.shape[1]
        controller = RbfController(D, U, args.basis_functions, args.max_action, squash_sin,
                                   seed=args.seed)
        if getattr(args, "policy_init_var", 0.0):
            init_policy_near(controller, start_states[0], args.policy_init_var, args.seed)
        reward = position_reward(D, args.cost_width)
        if args.fine_cost_width:
            reward = CombinedRewards(D, [reward, position_reward(D, args.fine_cost_width)])
        bumps = (limit_bumps(D, joint_limits, args.limit_cost)
                 if getattr(args, "limit_cost", 0.0) and joint_limits is not None else None)
        if bumps is not None:
            reward = CombinedRewards(D, [reward, bumps], [1.0, -args.limit_cost_weight])
        agent = PILCO(data, controller, reward, horizon=args.planning_horizon or args.horizon,
                      m_init=start_states[0:1], S_init=args.start_var * np.eye(D))
        set_gp_priors(agent, args)
        after_model_fit(args)(agent)
        return agent

    return build


def init_policy_near(controller, x0: np.ndarray, var: float, seed: int) -> None:
    """The MATLAB release's initial policy, around ``x0 [D]``: RBF centres drawn from
    N(x0, var·I), targets from N(0, 0.1²) (lengthscales stay 1); see
    :meth:`pilco.controllers.RbfController.place_near`."""
    controller.place_near(x0, np.sqrt(var), seed=seed)


def limit_bumps(state_dim: int, joint_limits: np.ndarray, width: float):
    """An :class:`~pilco.rewards.AxisBumpsReward` with one bump of ``width`` [rad] per
    finite joint limit, centred on the limit of joint ``j`` (state dim ``3 + j``), highest
    (1) at the limit; ``None`` when no joint is limited. Subtracted from the reward, the
    bumps keep the predicted joint angles away from the limits, where the real joint
    stops but the GP model, which rarely sees a joint at its limit, predicts it moving
    on."""
    from ..rewards import AxisBumpsReward

    limits = np.asarray(joint_limits, dtype=np.float64)
    dims, centres = [], []
    for j, bounds in enumerate(limits):
        for value in bounds:
            if np.isfinite(value):
                dims.append(3 + j)
                centres.append(value)
    if not dims:
        return None
    return AxisBumpsReward(state_dim, dims, centres, np.full(len(dims), float(width)))


def set_gp_priors(agent, args: argparse.Namespace) -> None:
    """With ``--gp-priors paper``, put :data:`PAPER_GP_PRIORS` on every output GP of
    ``agent.mgpr`` (before its first training: the compiled training loss includes the
    priors it saw when it was traced). Called on new and on resumed agents, since
    ``agent.npz`` keeps hyperparameter values, not priors."""
    if getattr(args, "gp_priors", "none") != "paper":
        return
    import tensorflow as tf
    import tensorflow_probability as tfp

    for model in agent.mgpr.models:
        for name, (shape, scale) in PAPER_GP_PRIORS.items():
            getattr(model.kernel, name).prior = tfp.distributions.Gamma(
                tf.constant(shape, tf.float64), tf.constant(1.0 / scale, tf.float64))


def position_weights(state_dim: int, width: float) -> np.ndarray:
    """``W [D, D]`` of a saturating cost of ``width`` [m] on the gripper position (state
    dims 0..2)."""
    W = np.zeros((state_dim, state_dim))
    W[:3, :3] = np.eye(3) / width ** 2
    return W


def main_position_reward(reward):
    """The reacher's main position cost inside its (possibly nested) combined reward:
    the first component, all the way down."""
    while hasattr(reward, "base_rewards"):
        reward = reward.base_rewards[0]
    return reward


def schedule(args: argparse.Namespace):
    """``(agent, episode number) -> None`` run before every policy search: in the first
    ``--early-episodes`` learned episodes the main cost has width ``--early-cost-width``
    and the initial state variance is ``--early-start-var`` (when set), afterwards the
    flags' ``--cost-width`` and ``--start-var``. Works on a resumed agent too: it sets
    both every time."""
    early_width = getattr(args, "early_cost_width", 0.0)
    early_var = getattr(args, "early_start_var", 0.0)

    def before_policy_search(agent, number: int) -> None:
        early = number - args.random_episodes <= args.early_episodes
        if early_width:
            width = early_width if early else args.cost_width
            main_position_reward(agent.reward).W.assign(
                position_weights(agent.state_dim, width))
        if early_var:
            D = agent.state_dim
            agent.S_init = (early_var if early else args.start_var) * np.eye(D)

    return before_policy_search


def after_model_fit(args: argparse.Namespace):
    """``agent -> None`` run after building the agent and every model fit:
    :func:`ignore_constant_inputs` unless ``--constant-input-lengthscale 0``."""
    ell = args.constant_input_lengthscale

    def adjust(agent) -> None:
        if ell:
            ignore_constant_inputs(agent, ell)

    return adjust


def reached_within(steps: int):
    """``summary -> bool``: the last episode reached the target within ``steps`` steps."""

    def success(summary: Dict[str, Any]) -> bool:
        last = summary["episodes"][-1] if summary["episodes"] else None
        return bool(last is not None and not last["random"]
                    and last["steps_to_target"] is not None
                    and last["steps_to_target"] <= steps)

    return success


def make_experiment(args: argparse.Namespace, task: str = "reacher",
                    damaged: bool = False, success_fn=None, wrap_env=None) -> Experiment:
    """A new run in ``args.output``, or the one saved there with ``--resume``;
    ``wrap_env(env) -> env`` wraps the env (e.g. to add an observation)."""
    from .. import plotting

    config = make_config(args, task, damaged)
    # the reward needs the target: the env is made here and handed to the experiment
    env = make_env(config.env_id, config.env_kwargs, render=False)
    if wrap_env is not None:
        env = wrap_env(env)
    target = env.unwrapped.target
    if args.target_spread > 0:
        check_drawn_target(env)

    def render(episode):
        return plotting.replay_fetch_frames(episode.states[:, 3:10], target,
                                            *args.render_size)

    build = agent_builder(args, target, env.unwrapped.joint_limits)
    exp = open_experiment(args, config, build, make_env=lambda: env,
                          render_fn=render, after_model_fit=after_model_fit(args),
                          before_policy_search=schedule(args),
                          success_fn=success_fn or reached_within(SUCCESS_STEPS))
    if exp.agent is not None:  # resumed from agent.npz, which holds no priors
        set_gp_priors(exp.agent, args)
    return exp


def figures(exp: Experiment, title: str) -> List[str]:
    """Distances, predicted vs real cost, one- and multi-step predictions, the final
    episode as a GIF; returns the written paths."""
    from .. import plotting

    return plotting.save_all(exp, exp.directory, title=title, state_dims=(0, 1, 2),
                             state_names=("x", "y", "z"), distance_label="distance to target [m]",
                             threshold=exp.config.success_threshold)


def parse_args(argv: Optional[Sequence[str]] = None,
               damaged: bool = False) -> argparse.Namespace:
    """The parsed flags (``--resume`` restores the saved ones); sets up logging."""
    return parse_task_args(build_parser(damaged), argv, ADDED_LATER)


def main(argv: Optional[Sequence[str]] = None, damaged: bool = False) -> int:
    """Run the task as ``examples/reacher.py`` does; returns the exit status."""
    task = "damaged_reacher" if damaged else "reacher"
    args = parse_args(argv, damaged)
    exp = make_experiment(args, task, damaged)
    summary = exp.run()
    return finish(exp, summary, args, title=f"Timing ({task}, seed {args.seed})",
                  reference=PAPER_SECONDS,
                  figures=lambda: figures(exp, task.replace("_", " ")))
