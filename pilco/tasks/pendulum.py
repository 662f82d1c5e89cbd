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

from typing import List

import numpy as np

from ..experiment import Experiment, ExperimentConfig
from .base import LastEpisodeHooks, Task
from .settings import (RunSettings, non_negative_float, positive_float, positive_int, setting,
                       task_settings)

__all__ = ["TARGET", "WEIGHTS", "M_INIT", "S_INIT", "PendulumSettings", "PendulumTask",
           "PENDULUM"]

#: the reward's target (upright, at rest) and weights, on ``[cos θ, sin θ, θ̇]``
TARGET = np.array([1.0, 0.0, 0.0])
WEIGHTS = np.diag([2.0, 2.0, 0.3])
#: the start distribution the policy is optimised from (hanging down)
M_INIT = np.array([[-1.0, 0.0, 0.0]])
S_INIT = np.diag([0.01, 0.05, 0.01])


@task_settings(episodes=12, random_episodes=4, horizon=40, basis_functions=30,
               policy_iters=50, model_iters=50, policy_restarts=2, model_restarts=2,
               output="runs/pendulum-seed{seed}")
class PendulumSettings(RunSettings):
    """The pendulum's settings (the reference port's workload)."""

    max_action: float = setting(2.0, "torque bound [N m]", kind=positive_float)
    substeps: int = setting(3, "Pendulum-v1 steps (0.05 s) each action is held for",
                            kind=positive_int)
    start_std: float = setting(0.05, "std of θ - π and θ̇ at the start (hanging down)",
                               kind=non_negative_float)
    noise_variance: float = setting(1e-3, "the GPs' noise variance, fixed (0: learned)",
                                    kind=non_negative_float)
    threshold: float = setting(0.3, "up: |θ| below this [rad] ...", kind=positive_float)
    hold_steps: int = setting(10, "... for the last N steps", kind=positive_int)


class PendulumTask(Task):
    """The reference port's pendulum swing-up."""

    name = "pendulum"
    settings = PendulumSettings
    description = "PILCO pendulum swing-up (Pendulum-v1)"

    def config(self, s: PendulumSettings) -> ExperimentConfig:
        from ..envs import PENDULUM_ID

        return self.loop_config(
            s, env_id=PENDULUM_ID,
            env_kwargs=dict(substeps=s.substeps, start_std=s.start_std,
                            max_episode_steps=s.horizon),
            random_action_scale=s.max_action, cost_width=float(np.sqrt(0.5)),
            success_threshold=s.threshold, solved_rule="hold", hold_steps=s.hold_steps)

    def agent_builder(self, s: PendulumSettings, env):
        """``(data, start_states) -> PILCO`` with the port's policy, reward and start."""
        import gpflow

        from ..controllers import RbfController
        from ..models import PILCO
        from ..rewards import ExponentialReward

        def build(data, start_states):  # the start distribution is known
            controller = RbfController(3, 1, s.basis_functions, max_action=s.max_action,
                                       seed=s.seed)
            agent = PILCO(data, controller, ExponentialReward(3, W=WEIGHTS, t=TARGET),
                          horizon=s.horizon, m_init=M_INIT, S_init=S_INIT)
            if s.noise_variance > 0:
                for model in agent.mgpr.models:
                    model.likelihood.variance.assign(s.noise_variance)
                    gpflow.set_trainable(model.likelihood.variance, False)
            return agent

        return build

    run_hooks = LastEpisodeHooks

    def figures(self, exp: Experiment, s: PendulumSettings) -> List[str]:
        """|θ| per step, predicted vs real cost, one- and multi-step predictions, the
        final episode as a GIF."""
        from .. import plotting

        return plotting.save_all(exp, exp.directory, title="pendulum swing-up",
                                 state_dims=(1, 2), state_names=("sin θ", "θ̇ [rad/s]"),
                                 distance_label="|θ| from upright [rad]",
                                 threshold=s.threshold)


PENDULUM = PendulumTask()
