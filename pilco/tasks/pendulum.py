"""The reference Python port's pendulum swing-up as a task (the workload of
``examples/pendulum.py``, run by :class:`~pilco.experiment.Experiment`).

gymnasium's Pendulum-v1 hanging down, each action held for 3 of its 0.05 s steps
(``pilco/PendulumSwingUp-v0``), observations ``[cos θ, sin θ, θ̇]``. Defaults: 4
episodes of random torques uniform in ±2 N m, then 8 learned ones ("iterations"), 40
steps each and a horizon of 40; an RBF policy of 30 basis functions with the sine
squashing to ±2 N m; the saturating reward around upright ``t = [1, 0, 0]`` with
``W = diag(2, 2, 0.3)`` from ``m_init = [-1, 0, 0]``, ``S_init = diag(0.01, 0.05,
0.01)``; the GPs' noise variance fixed at 1e-3; ``optimize_models(maxiter=50,
restarts=2)`` and ``optimize_policy(maxiter=50, restarts=2)`` (L-BFGS-B) every
iteration, without early stops.

"Up": |θ| < 0.3 rad for the last 10 steps of an episode. ``solved_at_episode`` is the
first learned episode that is up (iteration k is episode 4 + k); "success": the last
episode is up. The summary's ``cost`` is the saturating cost of |θ| with width
1/√2 rad, the angle part of the reward (``exp(-4 sin²(θ/2)) ≈ exp(-θ²)``).
"""
from __future__ import annotations

import argparse
from typing import List, Optional, Sequence

import numpy as np

from ..experiment import Experiment, ExperimentConfig
from ..experiment.cli import (add_common_arguments, finish, learning_settings,
                              non_negative_float, open_experiment, parse_task_args,
                              positive_float, positive_int)
from ..experiment.scoring import solved_in_last_episode

__all__ = ["TARGET", "WEIGHTS", "M_INIT", "S_INIT", "build_parser", "agent_builder",
           "make_config", "make_experiment", "figures", "parse_args", "main"]

#: the reward's target (upright, at rest) and weights, on ``[cos θ, sin θ, θ̇]``
TARGET = np.array([1.0, 0.0, 0.0])
WEIGHTS = np.diag([2.0, 2.0, 0.3])
#: the start distribution the policy is optimised from (hanging down)
M_INIT = np.array([[-1.0, 0.0, 0.0]])
S_INIT = np.diag([0.01, 0.05, 0.01])


def build_parser() -> argparse.ArgumentParser:
    """Every flag of the pendulum task (common flags with the port's defaults)."""
    parser = argparse.ArgumentParser(description="PILCO pendulum swing-up (Pendulum-v1)",
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    add_common_arguments(parser, episodes=12, random_episodes=4, steps=40,
                         basis_functions=30, policy_iters=50, model_iters=50,
                         policy_restarts=2, model_restarts=2,
                         output="runs/pendulum-seed{seed}")
    g = parser.add_argument_group("pendulum")
    g.add_argument("--max-action", type=positive_float, default=2.0, help="torque bound [N m]")
    g.add_argument("--substeps", type=positive_int, default=3,
                   help="Pendulum-v1 steps (0.05 s) each action is held for")
    g.add_argument("--start-std", type=non_negative_float, default=0.05,
                   help="std of θ - π and θ̇ at the start (hanging down)")
    g.add_argument("--noise-variance", type=non_negative_float, default=1e-3,
                   help="the GPs' noise variance, fixed (0: learned)")
    g.add_argument("--threshold", type=positive_float, default=0.3,
                   help="up: |θ| below this [rad] ...")
    g.add_argument("--hold-steps", type=positive_int, default=10, help="... for the last N steps")
    return parser


def agent_builder(args: argparse.Namespace):
    """``(data, start_states) -> PILCO`` for the pendulum with the settings in ``args``."""
    import gpflow

    from ..controllers import RbfController
    from ..models import PILCO
    from ..rewards import ExponentialReward

    def build(data, start_states):  # noqa: ARG001 - the start distribution is known
        controller = RbfController(3, 1, args.basis_functions, max_action=args.max_action,
                                   seed=args.seed)
        agent = PILCO(data, controller, ExponentialReward(3, W=WEIGHTS, t=TARGET),
                      horizon=args.horizon, m_init=M_INIT, S_init=S_INIT)
        if args.noise_variance > 0:
            for model in agent.mgpr.models:
                model.likelihood.variance.assign(args.noise_variance)
                gpflow.set_trainable(model.likelihood.variance, False)
        return agent

    return build


def make_config(args: argparse.Namespace) -> ExperimentConfig:
    """The run's settings from the parsed flags."""
    from ..envs import PENDULUM_ID

    return ExperimentConfig(
        task="pendulum", env_id=PENDULUM_ID, seed=args.seed, episodes=args.episodes,
        random_episodes=args.random_episodes, steps=args.horizon,
        env_kwargs=dict(substeps=args.substeps, start_std=args.start_std,
                        max_episode_steps=args.horizon),
        random_action_scale=args.max_action, **learning_settings(args),
        cost_width=float(np.sqrt(0.5)), success_threshold=args.threshold,
        solved_rule="hold", hold_steps=args.hold_steps, render=not args.no_render,
        predictions=not args.no_figures, quiet=args.quiet,
    )


def make_experiment(args: argparse.Namespace) -> Experiment:
    """A new run in ``args.output``, or the one saved there with ``--resume``."""
    config, build = make_config(args), agent_builder(args)
    return open_experiment(args, config, build, success_fn=solved_in_last_episode(config))


def figures(exp: Experiment, args: argparse.Namespace) -> List[str]:
    """|θ| per step, predicted vs real cost, one- and multi-step predictions, the final
    episode as a GIF; returns the written paths."""
    from .. import plotting

    return plotting.save_all(exp, exp.directory, title="pendulum swing-up",
                             state_dims=(1, 2), state_names=("sin θ", "θ̇ [rad/s]"),
                             distance_label="|θ| from upright [rad]",
                             threshold=args.threshold)


def parse_args(argv: Optional[Sequence[str]] = None) -> argparse.Namespace:
    """The parsed flags (``--resume`` restores the saved ones); sets up logging."""
    return parse_task_args(build_parser(), argv)


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run the task (``python -m pilco.tasks pendulum``); returns the exit status."""
    args = parse_args(argv)
    exp = make_experiment(args)
    summary = exp.run()
    return finish(exp, summary, args,
                  title=f"Timing (pendulum, seed {args.seed}, {len(summary['episodes'])} "
                        f"episodes)", figures=lambda: figures(exp, args))
