"""PILCO on any gymnasium environment with Box observations and actions: the ``gym`` task.

``pilco run gym --env ID`` learns on ``gymnasium.make(ID, **--env-kwargs)`` wrapped by
:class:`pilco.envs.gym_adapter.GymAdapter`: the state is the observation, each action is
held for ``--action-repeat`` steps, and the reward PILCO maximises is the saturating
``exp(-distance² / 2)`` of the state's distance to ``--target`` in cost widths
(``--widths``, one per state dimension or one for all; ``inf`` leaves a dimension out).
The policy is an RBF network of ``--basis-functions`` with actions bounded by
``--max-action`` (default: the action space's bound); ``--angles`` names state dimensions
that are angles (the policy and the dynamics model then see their sine and cosine). The
policy is optimised from the mean of the episodes' start states with covariance
``--start-var`` times the identity, over ``--planning-horizon`` steps (default
``--horizon``).

The run draws its figures but no frames of the environment (an arbitrary environment's
renderer may need packages that are not installed, and MuJoCo's may not run in a process
that loaded TensorFlow).

Success (stated before a run, as ``--success``): ``survive``, the last episode lasted
``--success-steps`` steps (default ``--horizon``: for an environment that terminates when
it fails, e.g. a pole that falls; an episode that ends early keeps its data), or
``hold``, its last ``--success-steps`` states all within ``--success-distance`` cost
widths of the target.

Presets (``--preset NAME``) hold other libraries' examples on gymnasium's current
versions: ``inverted-pendulum``, the reference GPflow port's ``inverted_pendulum.py``;
``torchrl``, TorchRL's PILCO example (both on InvertedPendulum-v5); see :data:`PRESETS`.
"""
from __future__ import annotations

import dataclasses
import json
from typing import Any, Dict, List, Optional

import numpy as np

from ..experiment import ExperimentConfig
from .base import LastEpisodeHooks, Task
from .settings import (RunSettings, non_negative_float, positive_float, positive_int, setting,
                       task_settings)

__all__ = ["GymSettings", "GymTask", "GYM", "PRESETS"]

#: other libraries' examples on gymnasium's current versions; what each leaves out
PRESETS: Dict[str, Dict[str, Any]] = {
    # the reference port: 5 random rollouts of 40 steps, 10 basis functions, horizon 40,
    # then 3 iterations of 100-step rollouts. Here every episode has --horizon steps, so
    # the random ones run 100 steps too (the planning horizon stays 40).
    "inverted-pendulum": dict(env="InvertedPendulum-v5", random_episodes=5, episodes=8,
                              horizon=100, planning_horizon=40, basis_functions=10,
                              success="survive", success_steps=100),
    # TorchRL's example: 200 random steps in one rollout that resets whenever the pole
    # falls (episodes of 3-23 steps), a start N(0, 1e-3 I), horizon 40, then 3 learning
    # epochs, each evaluated on 100 steps with the policy's mean action (and its
    # transitions added). Here: 20 random episodes (about 110-150 random steps), each
    # learned episode is the evaluation. Not carried over: its 100 Adam steps per epoch
    # (the policy search is this project's), and its data cap (the last 350 transitions).
    "torchrl": dict(env="InvertedPendulum-v5", random_episodes=20, episodes=23, horizon=100,
                    planning_horizon=40, basis_functions=10, start_var=1e-3,
                    success="survive", success_steps=100),
}


def _json_object(text: str) -> str:
    """A JSON object (the environment's keyword arguments), kept as text."""
    import argparse

    try:
        value = json.loads(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"expected a JSON object, got {text!r} ({err})") \
            from None
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError(f"expected a JSON object, got {text!r}")
    return text


@task_settings(episodes=8, random_episodes=1, horizon=40, basis_functions=10,
               policy_iters=50, output="runs/gym-seed{seed}")
class GymSettings(RunSettings):
    """The gym task's settings: the environment, the cost, the policy and the success."""

    env: str = setting("InvertedPendulum-v5", "gymnasium environment id")
    env_kwargs: str = setting("{}", "keyword arguments of gymnasium.make, as a JSON object",
                              kind=_json_object, metavar="JSON")
    target: Optional[tuple] = setting(None, "target state, one number per state dimension",
                                      kind=float, nargs="+", metavar="X", unset="zeros")
    widths: tuple = setting((1.0,), "cost width of each state dimension, or one for all "
                            "(inf: not in the cost)", kind=float, nargs="+", metavar="W")
    angles: Optional[tuple] = setting(None, "state dimensions that are angles (seen as sine "
                                      "and cosine)", kind=int, nargs="+", metavar="I",
                                      unset="none")
    action_repeat: int = setting(1, "environment steps each action is held for",
                                 kind=positive_int)
    max_action: Optional[float] = setting(
        None, "bound of the policy's actions", kind=positive_float,
        unset="the action space's bound")
    start_var: float = setting(0.01, "variance of the start distribution the policy is "
                               "optimised from (times the identity)", kind=positive_float)
    planning_horizon: Optional[int] = setting(
        None, "steps of the policy objective's prediction", kind=positive_int,
        unset="--horizon")
    success: str = setting("survive", "success rule of the last episode: it lasted "
                           "--success-steps steps, or held the target for them",
                           choices=("survive", "hold"))
    success_steps: Optional[int] = setting(None, "steps of the success rule",
                                           kind=positive_int, unset="--horizon")
    success_distance: float = setting(1.0, "hold: the distance to the target in cost widths",
                                      kind=non_negative_float)


class GymTask(Task):
    """PILCO on a gymnasium environment named on the command line."""

    name = "gym"
    settings = GymSettings
    description = "PILCO on any gymnasium environment with Box observations and actions"
    presets = PRESETS

    def check(self, s: GymSettings) -> GymSettings:
        """The environment is made once here, so that an unknown id, a space that is not a
        Box or a target of the wrong length is a usage error before any episode."""
        self._adapter(s).close()
        return s

    def _adapter(self, s: GymSettings):
        import gymnasium

        from ..envs.gym_adapter import GymAdapter

        try:
            env = gymnasium.make(s.env, **json.loads(s.env_kwargs))
        except (gymnasium.error.Error, TypeError, ImportError) as err:
            raise ValueError(f"--env {s.env}: cannot make the environment ({err})") from None
        try:
            adapter = GymAdapter(env, s.target or (), s.widths, s.action_repeat)
        except (TypeError, ValueError) as err:
            env.close()
            raise ValueError(f"--env {s.env}: {err}") from None
        D = adapter.observation_space.shape[0]
        bad = [i for i in s.angles or () if not 0 <= i < D]
        if bad:
            adapter.close()
            raise ValueError(f"--angles {bad}: the state has dimensions 0-{D - 1}")
        return adapter

    def config(self, s: GymSettings) -> ExperimentConfig:
        """The loop's config; never rendering: an arbitrary environment's renderer may
        need packages that are not installed (pygame) or, for MuJoCo, may not run in a
        process that loaded TensorFlow."""
        hold = s.success == "hold"
        config = self.loop_config(
            s, env_id=s.env, env_kwargs=json.loads(s.env_kwargs), random_action_scale=None,
            cost_width=1.0, success_threshold=s.success_distance if hold else 1.0,
            solved_rule=s.success, hold_steps=s.success_steps or s.horizon)
        return dataclasses.replace(config, render=False)

    def make_env(self, s: GymSettings, config: ExperimentConfig):
        return self._adapter(s)

    def agent_builder(self, s: GymSettings, env):
        """``(data, start_states) -> PILCO``: an RBF policy on the state (angles as sine
        and cosine), the saturating reward of the distance in cost widths, the start
        distribution from the episodes' start states."""
        from ..controllers import RbfController
        from ..models import PILCO
        from ..rewards import ExponentialReward

        D = env.observation_space.shape[0]
        U = env.action_space.shape[0]
        bound = (s.max_action if s.max_action is not None
                 else float(np.min(np.abs(env.action_space.high))))
        inverse = np.where(np.isfinite(env.widths), 1.0 / env.widths ** 2, 0.0)

        def build(data, start_states):
            angles = list(s.angles or ())
            controller = RbfController(D + len(angles), U, s.basis_functions,
                                       max_action=bound, seed=s.seed)
            reward = ExponentialReward(D, W=np.diag(inverse), t=env.target)
            m_init = np.mean(np.asarray(start_states, dtype=np.float64), axis=0)[None, :]
            return PILCO(data, controller, reward, horizon=s.planning_horizon or s.horizon,
                         m_init=m_init, S_init=s.start_var * np.eye(D),
                         angle_indices=angles)

        return build

    run_hooks = LastEpisodeHooks

    def figures(self, exp, s: GymSettings) -> List[str]:
        """Distances per step, predicted vs real cost, one- and multi-step predictions of
        the first state dimensions (no frames: :meth:`config`)."""
        from .. import plotting

        D = exp.make_env().observation_space.shape[0]
        return plotting.save_all(exp, exp.directory, title=s.env,
                                 state_dims=tuple(range(min(D, 3))),
                                 distance_label="distance to the target [cost widths]",
                                 threshold=s.success_distance if s.success == "hold" else None)

    def notes(self, summary: Dict[str, Any]) -> List[str]:
        steps = [e["steps"] for e in summary["episodes"]]
        return [f"\nsteps per episode: {steps}"]


GYM = GymTask()
