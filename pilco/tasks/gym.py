"""PILCO on any gymnasium environment with Box observations and actions: the ``gym`` task.

``pilco run gym --env ID`` learns on ``gymnasium.make(ID, **--env-kwargs)`` wrapped by
:class:`pilco.envs.gym_adapter.GymAdapter`: the state is the observation, each action is
held for ``--action-repeat`` steps, and the reward PILCO maximises is the saturating
``exp(-distance² / 2)`` of the state's distance to ``--target`` in cost widths
(``--widths``, one per state dimension or one for all; ``inf`` leaves a dimension out).
The policy is an RBF network of ``--basis-functions`` with actions bounded by
``--max-action`` (default: the action space's bound); ``--angles`` names state dimensions
that are angles (the policy and the dynamics model then see their sine and cosine). The
policy is optimised from the mean of the episodes' start states with variances
``--start-var``, over ``--planning-horizon`` steps (default
``--horizon``).

For locomotion the reward may add a linear term ``w·x`` (``--linear``, one weight per
state dimension, e.g. on the forward speed) and subtract saturating penalties
``exp(-(x_d - c)² / 2w²)`` near limits (``--penalties``, triples ``d c w``); with every
width ``inf`` the target term is left out.

The run draws its figures but no frames of the environment (an arbitrary environment's
renderer may need packages that are not installed, and MuJoCo's may not run in a process
that loaded TensorFlow).

Success (stated before a run, as ``--success``): ``survive``, the last episode lasted
``--success-steps`` steps (default ``--horizon``: for an environment that terminates when
it fails, e.g. a pole that falls; an episode that ends early keeps its data), or
``hold``, its last ``--success-steps`` states all within ``--success-distance`` cost
widths of the target, or ``reach``, one of its states that close (e.g. a goal where the
environment ends the episode), or ``advance``, it travelled ``--success-distance`` along
the environment's ``info[--progress-key]`` (e.g. a swimmer's ``x_position``; the episodes'
distances are then what is left of that goal). The distance of ``hold`` and ``reach`` is
measured over ``--success-dims`` (default: the dimensions in the cost). ``--state-dims``
keeps some of the observation's dimensions as the state; ``--model-steps N`` trains the
dynamics model on the first N steps of each episode only. The start distribution's
variance (``--start-var``) and a fixed noise variance of the dynamics GPs
(``--noise-variance``; 0: learned) take one number per state dimension or one for all.

Presets (``--preset NAME``) hold other libraries' examples on gymnasium's current
versions: ``inverted-pendulum``, the reference GPflow port's ``inverted_pendulum.py``, and
``torchrl``, TorchRL's PILCO example (both on InvertedPendulum-v5);
``inverted-double-pendulum``, the port's ``inv_double_pendulum.py``; ``mountain-car``, the
port's ``mountain_car.py`` (MountainCarContinuous-v0); ``pendulum``, the port's
``pendulum_swing_up.py`` (Pendulum-v1 from hanging down); ``swimmer``, the port's
``swimmer.py`` (Swimmer-v5); see :data:`PRESETS`.
"""
from __future__ import annotations

import dataclasses
import json
import math
from typing import Any, Dict, List, Optional

import numpy as np

from ..experiment import ExperimentConfig
from ..experiment.episode import stack_transitions
from .base import LastEpisodeHooks, Task
from .settings import (RunSettings, non_negative_float, positive_float, positive_int, setting,
                       task_settings)

__all__ = ["GymSettings", "GymHooks", "GymTask", "GYM", "PRESETS"]

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
                    planning_horizon=40, basis_functions=10, start_var=(1e-3,),
                    success="survive", success_steps=100),
    # the reference port's mountain_car.py: 5 random rollouts of 25 steps, each action held
    # for 5 steps, 25 basis functions, then 5 learned episodes, 100 policy iterations with
    # 3 restarts. The port works in units of its random data's mean and standard deviation
    # (about 0.115 in position, 0.0095 in speed): the reward W = diag(0.5, 0.1), the start
    # 0.5 I and the GPs' noise variance 0.05 there are these widths, variances and noise
    # in the environment's units. Success: the car at the goal (x >= 0.45, where the
    # environment ends the episode), 0.05 or less from the target's x = 0.5.
    "mountain-car": dict(env="MountainCarContinuous-v0", action_repeat=5, horizon=25,
                         random_episodes=5, episodes=10, basis_functions=25,
                         policy_iters=100, policy_restarts=3, target=(0.5, 0.0),
                         widths=(0.16, 0.03), start_var=(0.0065, 4.5e-5),
                         noise_variance=(6.5e-4, 4.5e-6), success="reach", success_dims=(0,),
                         success_distance=0.05 / 0.16),
    # the reference port's inv_double_pendulum.py: 5 random rollouts of 40 steps, then 12
    # learned episodes of 130 steps, the model learning from the first 40 of each, horizon
    # 40, 40 basis functions, 10 iterations and 2 restarts for the GPs and the policy, the
    # GPs' noise variance 1e-3, the start N(0, 0.005 I), the reward W = 5 I but 1 on the
    # cart's position and speed. The port's state was the cart, the two angles and the
    # three speeds; InvertedDoublePendulum-v5 observes the angles as sines and cosines
    # (kept, each at the angle's width) and one constraint force (left out). Not carried
    # over: the port's extra ends of an episode (|x| > 0.9, a constraint force above 0.15;
    # v5 ends it when the tip falls below 1 m) and its stop at the first episode of more
    # than 120 steps. Success: the last learned episode lasts all 130 steps.
    "inverted-double-pendulum": dict(
        env="InvertedDoublePendulum-v5", state_dims=tuple(range(8)), random_episodes=5,
        episodes=17, horizon=130, planning_horizon=40, model_steps=40, basis_functions=40,
        policy_iters=10, policy_restarts=2, model_iters=10, model_restarts=2,
        target=(0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0),
        widths=(1.0,) + (1 / math.sqrt(5.0),) * 4 + (1.0,) + (1 / math.sqrt(5.0),) * 2,
        start_var=(0.005,), noise_variance=(1e-3,), success="survive", success_steps=130),
    # the reference port's pendulum_swing_up.py (the `pendulum` task's workload) on the
    # package's Pendulum-v1 that starts hanging down, as the port's reset does, each action
    # held for 3 steps: 4 random episodes, then 8 learned ones of 40 steps, 30 basis
    # functions, 50 iterations and 2 restarts for the GPs and the policy, the reward
    # W = diag(2, 2, 0.3) around upright on [cos θ, sin θ, θ̇], the start
    # diag(0.01, 0.05, 0.01), the GPs' noise variance 1e-3. Success: the `pendulum` task's
    # |θ| < 0.3 rad for the last 10 steps (on [cos θ, sin θ] in these widths: 2√2 sin 0.15).
    "pendulum": dict(env="pilco/PendulumSwingUp-v0", random_episodes=4, episodes=12,
                     horizon=40, basis_functions=30, policy_iters=50, policy_restarts=2,
                     model_iters=50, model_restarts=2, target=(1.0, 0.0, 0.0),
                     widths=(math.sqrt(0.5), math.sqrt(0.5), 1 / math.sqrt(0.3)),
                     start_var=(0.01, 0.05, 0.01), noise_variance=(1e-3,), success="hold",
                     success_dims=(0, 1), success_steps=10,
                     success_distance=2 * math.sqrt(2) * math.sin(0.15)),
    # the reference port's swimmer.py (its last version) on Swimmer-v5, whose observation
    # is the port's state: the three angles (body, two joints) and the five speeds. Each
    # action held for 5 steps (0.2 s); 10 random episodes, then 15 learned ones of 50
    # steps (10 s), the model learning from the first 15 steps of each (the port's
    # random rollouts were 15 steps long) and the policy planning over 15; 40 basis
    # functions, 80 iterations and 2 restarts for the GPs and the policy, the start
    # N(0, 0.005 I), the GPs' noise learned. The reward: the forward speed (dimension 3)
    # minus four saturating bumps at ±95° of each joint (W = 10 there, a width of
    # 1/√10 rad). Success, stated before any sweep: the last learned episode swims at
    # least 1 m forward in its 10 s (no random episode of 20 tried went 0.81 m; a
    # sinusoidal gait held open loop goes 1.0-1.4 m).
    "swimmer": dict(env="Swimmer-v5", action_repeat=5, random_episodes=10, episodes=25,
                    horizon=50, planning_horizon=15, model_steps=15, basis_functions=40,
                    policy_iters=80, policy_restarts=2, model_iters=80, model_restarts=2,
                    start_var=(0.005,), widths=(math.inf,),
                    linear=(0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0),
                    penalties=tuple(v for dim in (2, 1) for sign in (1.0, -1.0)
                                    for v in (float(dim), sign * math.radians(95.0),
                                              1 / math.sqrt(10.0))),
                    success="advance", progress_key="x_position", success_distance=1.0),
}


def _penalty_triples(penalties: Optional[tuple], D: int) -> List[tuple]:
    """``--penalties`` as ``(dimension, centre, width)`` triples, checked against the
    state's ``D`` dimensions and for a positive, finite width."""
    values = list(penalties or ())
    if len(values) % 3:
        raise ValueError(f"--penalties: triples DIM CENTRE WIDTH, got {len(values)} numbers")
    triples = []
    for k in range(0, len(values), 3):
        d, centre, width = values[k:k + 3]
        if d != int(d) or not 0 <= int(d) < D:
            raise ValueError(f"--penalties: the dimension {d} must be one of 0-{D - 1}")
        if not width > 0 or not np.isfinite(width):
            raise ValueError(f"--penalties: the width of the penalty on dimension {int(d)} "
                             f"must be a positive number, got {width}")
        triples.append((int(d), float(centre), float(width)))
    return triples


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
    state_dims: Optional[tuple] = setting(None, "the observation's dimensions kept as the "
                                          "state (--target, --widths, --angles refer to "
                                          "it)", kind=int, nargs="+", metavar="I",
                                          unset="all")
    model_steps: Optional[int] = setting(None, "the dynamics model learns from the first N "
                                         "steps of each episode", kind=positive_int,
                                         unset="every step")
    angles: Optional[tuple] = setting(None, "state dimensions that are angles (seen as sine "
                                      "and cosine)", kind=int, nargs="+", metavar="I",
                                      unset="none")
    action_repeat: int = setting(1, "environment steps each action is held for",
                                 kind=positive_int)
    max_action: Optional[float] = setting(
        None, "bound of the policy's actions", kind=positive_float,
        unset="the action space's bound")
    start_var: tuple = setting((0.01,), "variance of the start distribution the policy is "
                               "optimised from, per state dimension or one for all",
                               kind=positive_float, nargs="+", metavar="V")
    noise_variance: tuple = setting((0.0,), "the dynamics GPs' noise variance, fixed, per "
                                    "state dimension or one for all (0: learned)",
                                    kind=non_negative_float, nargs="+", metavar="V")
    planning_horizon: Optional[int] = setting(
        None, "steps of the policy objective's prediction", kind=positive_int,
        unset="--horizon")
    linear: Optional[tuple] = setting(None, "weights of a linear reward term w·x, one per "
                                      "state dimension (e.g. a forward speed)", kind=float,
                                      nargs="+", metavar="W", unset="none")
    penalties: Optional[tuple] = setting(
        None, "saturating penalties subtracted from the reward, as triples DIM CENTRE WIDTH: "
        "exp(-(x_DIM - CENTRE)^2 / 2 WIDTH^2) each (e.g. near a joint's limit)", kind=float,
        nargs="+", metavar="X", unset="none")
    success: str = setting("survive", "success rule of the last episode: it lasted "
                           "--success-steps steps, held the target for them, reached "
                           "it (a state within --success-distance), or advanced "
                           "--success-distance along --progress-key",
                           choices=("survive", "hold", "reach", "advance"))
    progress_key: str = setting("x_position", "advance: the environment's info number "
                                "whose growth over an episode is its progress")
    success_steps: Optional[int] = setting(None, "steps of the success rule",
                                           kind=positive_int, unset="--horizon")
    success_distance: float = setting(1.0, "hold, reach: the distance to the target in cost "
                                      "widths; advance: the progress to make",
                                      kind=non_negative_float)
    success_dims: Optional[tuple] = setting(
        None, "state dimensions of the success rule's distance", kind=int, nargs="+",
        metavar="I", unset="the dimensions in the cost")


class GymHooks(LastEpisodeHooks):
    """Success in the last episode; with ``--model-steps N`` the model learns from the
    first N steps of each episode (the reference port's double pendulum runs 130 steps and
    learns from the first 40)."""

    def model_data(self, run):
        n = self.settings.model_steps
        return (*stack_transitions(run.episodes, n), None) if n else None


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
        advance = s.success == "advance"
        try:
            adapter = GymAdapter(env, s.target or (), s.widths, s.action_repeat,
                                 distance_dims=s.success_dims or (),
                                 state_dims=s.state_dims or (),
                                 progress_key=s.progress_key if advance else "",
                                 progress_goal=s.success_distance if advance else 0.0)
        except (TypeError, ValueError) as err:
            env.close()
            raise ValueError(f"--env {s.env}: {err}") from None
        try:
            self._check_state_settings(s, adapter)
        except ValueError:
            adapter.close()
            raise
        return adapter

    @staticmethod
    def _check_state_settings(s: GymSettings, adapter) -> None:
        """The settings that refer to the state's dimensions, against the adapter's."""
        D = adapter.observation_space.shape[0]
        bad = [i for i in s.angles or () if not 0 <= i < D]
        if bad:
            raise ValueError(f"--angles {bad}: the state has dimensions 0-{D - 1}")
        for name in ("start_var", "noise_variance"):
            given = np.atleast_1d(getattr(s, name)).size
            if given not in (1, D):
                raise ValueError(f"--{name.replace('_', '-')}: one number or {D} (one per "
                                 f"state dimension), got {given}")
        if s.linear is not None and len(s.linear) != D:
            raise ValueError(f"--linear: {D} weights (one per state dimension), got "
                             f"{len(s.linear)}")
        _penalty_triples(s.penalties, D)
        if not np.any(np.isfinite(adapter.widths)) and s.linear is None:
            raise ValueError("--widths: every width is inf and there is no --linear term: "
                             "the reward has nothing to reward")
        if s.success == "advance":  # the key is read at a reset: fail here, not later
            adapter.reset(seed=0)

    def config(self, s: GymSettings) -> ExperimentConfig:
        """The loop's config; never rendering: an arbitrary environment's renderer may
        need packages that are not installed (pygame) or, for MuJoCo, may not run in a
        process that loaded TensorFlow."""
        near = s.success in ("hold", "reach")
        # advance: the distances are what is left of the goal, 0 once travelled
        threshold = s.success_distance if near else 1e-9 if s.success == "advance" else 1.0
        rule = "reach" if s.success == "advance" else s.success
        config = self.loop_config(
            s, env_id=s.env, env_kwargs=json.loads(s.env_kwargs), random_action_scale=None,
            cost_width=1.0, success_threshold=threshold,
            solved_rule=rule, hold_steps=s.success_steps or s.horizon)
        return dataclasses.replace(config, render=False)

    def make_env(self, s: GymSettings, config: ExperimentConfig):
        return self._adapter(s)

    def agent_builder(self, s: GymSettings, env):
        """``(data, start_states) -> PILCO``: an RBF policy on the state (angles as sine
        and cosine), the reward (:meth:`reward`), the start distribution centred on the
        mean of the episodes' start states, the GPs' noise variance fixed where
        ``--noise-variance`` gives one."""
        import gpflow

        from ..controllers import RbfController
        from ..models import PILCO

        D = env.observation_space.shape[0]
        U = env.action_space.shape[0]
        bound = (s.max_action if s.max_action is not None
                 else float(np.min(np.abs(env.action_space.high))))
        start_var = np.broadcast_to(np.atleast_1d(s.start_var).astype(np.float64), (D,))
        noise = np.broadcast_to(np.atleast_1d(s.noise_variance).astype(np.float64), (D,))

        def build(data, start_states):
            angles = list(s.angles or ())
            controller = RbfController(D + len(angles), U, s.basis_functions,
                                       max_action=bound, seed=s.seed)
            reward = self.reward(s, env)
            m_init = np.mean(np.asarray(start_states, dtype=np.float64), axis=0)[None, :]
            agent = PILCO(data, controller, reward, horizon=s.planning_horizon or s.horizon,
                          m_init=m_init, S_init=np.diag(start_var), angle_indices=angles)
            for model, variance in zip(agent.mgpr.models, noise):
                if variance > 0:
                    model.likelihood.variance.assign(variance)
                    gpflow.set_trainable(model.likelihood.variance, False)
            return agent

        return build

    @staticmethod
    def reward(s: GymSettings, env):
        """The saturating reward of the distance to the target in cost widths (left out
        when every width is ``inf``), plus ``--linear``'s ``w·x``, minus each of
        ``--penalties``' saturating bumps."""
        from ..rewards import CombinedRewards, ExponentialReward, LinearReward

        D = env.observation_space.shape[0]
        terms, coefs = [], []
        if np.any(np.isfinite(env.widths)):
            inverse = np.where(np.isfinite(env.widths), 1.0 / env.widths ** 2, 0.0)
            terms.append(ExponentialReward(D, W=np.diag(inverse), t=env.target))
            coefs.append(1.0)
        if s.linear is not None:
            terms.append(LinearReward(D, np.asarray(s.linear, dtype=np.float64)))
            coefs.append(1.0)
        for d, centre, width in _penalty_triples(s.penalties, D):
            W, t = np.zeros((D, D)), np.zeros(D)
            W[d, d], t[d] = 1.0 / width ** 2, centre
            terms.append(ExponentialReward(D, W=W, t=t))
            coefs.append(-1.0)
        if len(terms) == 1:
            return terms[0]
        return CombinedRewards(D, terms, coefs=coefs)

    run_hooks = GymHooks

    def figures(self, exp, s: GymSettings) -> List[str]:
        """Distances per step, predicted vs real cost, one- and multi-step predictions of
        the first state dimensions (no frames: :meth:`config`)."""
        from .. import plotting

        D = exp.make_env().observation_space.shape[0]
        return plotting.save_all(exp, exp.directory, title=s.env,
                                 state_dims=tuple(range(min(D, 3))),
                                 distance_label=(f"{s.progress_key}: left of the goal"
                                                 if s.success == "advance" else
                                                 "distance to the target [cost widths]"),
                                 threshold=None if s.success in ("survive", "advance")
                                 else s.success_distance)

    def notes(self, summary: Dict[str, Any]) -> List[str]:
        steps = [e["steps"] for e in summary["episodes"]]
        return [f"\nsteps per episode: {steps}"]


GYM = GymTask()
