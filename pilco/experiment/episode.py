"""One episode on a gymnasium environment: :class:`Episode` and :func:`rollout`."""
from __future__ import annotations

import dataclasses
import time
from typing import Any, Callable, Dict, List, Optional, Tuple

import numpy as np

from .progress import progress_bar
from .signals import raise_if_stop_requested

__all__ = ["Episode", "rollout", "make_env", "distance_from_info", "stack_transitions",
           "DISTANCE_KEYS", "EnvironmentContractError"]


@dataclasses.dataclass
class Episode:
    """One episode's record.

    Attributes:
        states: observations ``[T+1, D]`` (index 0 is the start).
        actions: actions applied ``[T, U]``.
        rewards: environment rewards ``[T]``.
        distances: task distance ``[T+1]`` of every state (NaN without a ``distance_fn``).
        frames: rendered RGB frames ``[T+1]`` of ``uint8 [H, W, 3]`` (empty unless rendered).
        seconds: wall time of the interaction.
        random: whether the actions were random.
        terminated: the environment ended the episode (e.g. target reached).
        interrupted: the rollout was stopped by ``KeyboardInterrupt``.
    """

    states: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    distances: np.ndarray
    frames: List[np.ndarray] = dataclasses.field(default_factory=list)
    seconds: float = 0.0
    random: bool = False
    terminated: bool = False
    interrupted: bool = False

    @property
    def steps(self) -> int:
        """Number of transitions ``T``."""
        return int(len(self.actions))

    def transitions(self) -> Tuple[np.ndarray, np.ndarray]:
        """Training pairs: ``X [T, D+U] = [x_t, u_t]`` and ``Y [T, D] = x_{t+1} - x_t``."""
        X = np.concatenate([self.states[:-1], self.actions], axis=1)
        Y = self.states[1:] - self.states[:-1]
        return X, Y


def stack_transitions(episodes, steps: Optional[int] = None) -> Tuple[np.ndarray, np.ndarray]:
    """The training pairs of ``episodes`` one after the other (of each only its first
    ``steps``, when given): ``X [N, D+U]``, ``Y [N, D]``."""
    pairs = [e.transitions() for e in episodes]
    return (np.concatenate([X[:steps] for X, _ in pairs]),
            np.concatenate([Y[:steps] for _, Y in pairs]))


class EnvironmentContractError(ValueError):
    """An environment that does not report what the loop needs of it (the task distance
    in ``info``)."""


#: the ``info`` keys the loop reads the task distance from, the first one present
DISTANCE_KEYS = ("distance", "tip_distance")


def distance_from_info(env, info: Dict[str, Any]) -> float:
    """The task distance an env reports in ``info`` (:data:`DISTANCE_KEYS`): the default
    ``distance_fn``. Raises :class:`EnvironmentContractError` naming the contract when
    ``info`` holds none of them (at the first reset, before any step is taken): every
    episode's score (closest and final distance, solved or not) is read from it."""
    for key in DISTANCE_KEYS:
        if key in info:
            return float(info[key])
    name = getattr(getattr(env, "spec", None), "id", None) or type(env).__name__
    raise EnvironmentContractError(
        f"environment {name} reports no task distance: the info of reset() and step() "
        f"holds none of {', '.join(map(repr, DISTANCE_KEYS))} (it holds "
        f"{sorted(map(str, info)) or 'nothing'}). pilco scores every episode by the "
        f"distance of each state to the goal: put it in info as 'distance', or give the "
        f"task's RunHooks a distance(env, info) -> float")


def make_env(env_id: str, env_kwargs: Optional[Dict[str, Any]] = None, render: bool = False):
    """``gymnasium.make(env_id, **env_kwargs)`` with pilco's ids registered;
    ``render_mode="rgb_array"`` when ``render``."""
    import gymnasium

    import pilco.envs  # noqa: F401 - registers the ids

    return gymnasium.make(env_id, render_mode="rgb_array" if render else None,
                          **(env_kwargs or {}))


def rollout(env, policy_fn: Optional[Callable[[np.ndarray], np.ndarray]], steps: int,
            seed: Optional[int] = None, random: bool = False,
            random_action: Optional[Callable[[np.random.Generator], np.ndarray]] = None,
            distance_fn: Optional[Callable[[Any, dict], float]] = None,
            render: bool = False, quiet: bool = True, desc: str = "interaction",
            reset_options: Optional[dict] = None) -> Episode:
    """Run one episode of at most ``steps`` steps.

    Args:
        env: a gymnasium env (observation ``[D]``, action ``[U]``).
        policy_fn: ``x [D] -> u [U]`` (or ``[1, U]``); ignored when ``random``.
        steps: maximum number of steps (the episode also ends when the env terminates
            or truncates).
        seed: seed of ``env.reset`` and of the random actions.
        random: draw actions with ``random_action(rng)`` (default: uniform over
            ``env.action_space``) instead of ``policy_fn``.
        distance_fn: ``(env, info) -> float`` task distance, recorded for every state.
        render: keep ``env.render()`` frames (the env needs ``render_mode="rgb_array"``).
        quiet: no progress bar.
        reset_options: passed to ``env.reset(options=...)``.

    Returns:
        An :class:`Episode`. A ``KeyboardInterrupt`` (or SIGTERM, see
        :mod:`pilco.experiment.signals`) during the steps returns the partial episode with
        ``interrupted=True``: its complete transitions are kept, the caller decides.
    """
    if not random and policy_fn is None:
        raise ValueError("rollout needs a policy_fn unless random=True")
    rng = np.random.default_rng(seed)
    if random and random_action is None:
        space = env.action_space
        low, high = np.asarray(space.low, float), np.asarray(space.high, float)
        random_action = lambda g: g.uniform(low, high)  # noqa: E731
    t0 = time.perf_counter()
    x, info = env.reset(seed=seed, options=reset_options)
    x = np.asarray(x, dtype=np.float64).reshape(-1)
    states, actions, rewards = [x], [], []
    distances = [distance_fn(env, info) if distance_fn else np.nan]
    frames = [env.render()] if render else []
    terminated = interrupted = False
    bar = progress_bar(steps, desc, quiet, unit="step")
    try:
        for _ in range(int(steps)):
            raise_if_stop_requested()
            if random:
                u = np.asarray(random_action(rng), dtype=np.float64).reshape(-1)
            else:
                u = np.asarray(policy_fn(x), dtype=np.float64).reshape(-1)
            x_next, r, terminated, truncated, info = env.step(u)
            x = np.asarray(x_next, dtype=np.float64).reshape(-1)
            actions.append(u)
            states.append(x)
            rewards.append(float(r))
            distances.append(distance_fn(env, info) if distance_fn else np.nan)
            if render:
                frames.append(env.render())
            bar.update(1)
            if terminated or truncated:
                break
    except KeyboardInterrupt:
        interrupted = True
        # keep only complete transitions
        states = states[: len(actions) + 1]
        distances = distances[: len(actions) + 1]
    finally:
        bar.close()
    U = int(np.prod(env.action_space.shape))
    return Episode(
        states=np.array(states),
        actions=np.array(actions).reshape(-1, U),
        rewards=np.array(rewards),
        distances=np.array(distances, dtype=np.float64),
        frames=frames,
        seconds=time.perf_counter() - t0,
        random=bool(random),
        terminated=bool(terminated),
        interrupted=interrupted,
    )
