"""Any gymnasium environment with Box observations and actions, as the PILCO loop reads one.

:class:`GymAdapter` wraps an environment so that its ``info`` carries ``"distance"``, the
state's distance to a target in cost widths, ``sqrt(Σ_d ((x_d - t_d) / w_d)²)`` over the
dimensions with a finite width (the saturating reward ``exp(-distance² / 2)`` is the
task's) or over the dimensions named as ``distance_dims``, and holds each action for
``action_repeat`` of the environment's steps (their rewards summed; an episode that
terminates or is truncated during them ends there). The state is the observation as
float64, or the observation's dimensions named as ``state_dims`` (e.g. without a contact
force that a smooth model cannot follow). For locomotion, where the goal is a distance
travelled rather than a state, ``progress_key`` names a number of the environment's
``info`` (e.g. Swimmer's ``"x_position"``) and ``info["distance"]`` is what is left of
``progress_goal`` since the episode's start, ``max(0, goal - (info[key] - info₀[key]))``.
Bad settings (a non-Box space, a target or widths of the wrong length, a width that is not
positive) raise before any episode.
"""
from __future__ import annotations

from typing import Any, Sequence

import gymnasium
import numpy as np
from gymnasium import spaces

__all__ = ["GymAdapter", "box_dimension"]


def box_dimension(space: Any, what: str) -> int:
    """The size of a one-dimensional Box ``space``; TypeError naming ``what`` otherwise."""
    if not isinstance(space, spaces.Box) or len(space.shape) != 1:
        raise TypeError(f"the environment's {what} space must be a one-dimensional Box, got "
                        f"{space}")
    return int(space.shape[0])


class GymAdapter(gymnasium.Wrapper):
    """``env`` with ``info["distance"]`` to ``target`` in units of ``widths`` and each
    action held for ``action_repeat`` steps (module docstring).

    Args:
        env: a gymnasium environment with Box observation and action spaces.
        target: the target state [D] (default zeros).
        widths: the cost width of each state dimension [D], or one for all (``inf``: the
            dimension is not in the cost).
        action_repeat: environment steps per step of PILCO (the reference port's SUBS).
        distance_dims: the state dimensions of ``info["distance"]`` (default: those with a
            finite width); each needs a finite width.
        state_dims: the observation's dimensions kept as the state, in this order
            (default: all); ``target``, ``widths`` and ``distance_dims`` refer to the state.
        progress_key, progress_goal: ``info["distance"]`` is the part of ``progress_goal``
            not yet travelled along ``info[progress_key]`` (module docstring); the widths
            then need not have a finite one.
    """

    def __init__(self, env: gymnasium.Env, target: Sequence[float] = (),
                 widths: Sequence[float] = (1.0,), action_repeat: int = 1,
                 distance_dims: Sequence[int] = (), state_dims: Sequence[int] = (),
                 progress_key: str = "", progress_goal: float = 0.0) -> None:
        super().__init__(env)
        observed = box_dimension(env.observation_space, "observation")
        box_dimension(env.action_space, "action")
        self._kept = np.array([int(i) for i in state_dims] or range(observed), dtype=int)
        bad = [int(i) for i in self._kept if not 0 <= i < observed]
        if bad or len(set(self._kept.tolist())) < len(self._kept):
            raise ValueError(f"state dimensions {self._kept.tolist()}: each once, of the "
                             f"observation's 0-{observed - 1}")
        D = len(self._kept)
        target = np.zeros(D) if len(target) == 0 else np.asarray(target, dtype=np.float64)
        if target.shape != (D,) or not np.all(np.isfinite(target)):
            raise ValueError(f"target must be {D} finite numbers (the state's dimensions), "
                             f"got {list(np.ravel(target))}")
        widths = np.asarray(widths, dtype=np.float64).reshape(-1)
        if widths.size == 1:
            widths = np.full(D, widths[0])
        if widths.shape != (D,) or np.any(np.isnan(widths)) or np.any(widths <= 0):
            raise ValueError(f"widths must be one positive number or {D} (inf: not in the "
                             f"cost), got {list(widths)}")
        if not np.any(np.isfinite(widths)) and not progress_key:
            raise ValueError("at least one width must be finite: the distance needs a "
                             "dimension")
        if not np.isfinite(progress_goal) or progress_goal < 0:
            raise ValueError(f"progress_goal must be a finite number >= 0, got "
                             f"{progress_goal!r}")
        self.progress_key, self.progress_goal = str(progress_key), float(progress_goal)
        self._progress_start = 0.0
        if isinstance(action_repeat, bool) or not isinstance(action_repeat, (int, np.integer)) \
                or action_repeat < 1:
            raise ValueError(f"action_repeat must be an integer >= 1, got {action_repeat!r}")
        self.target, self.widths, self.action_repeat = target, widths, int(action_repeat)
        self._measured = np.isfinite(widths)
        if len(distance_dims):
            dims = [int(i) for i in distance_dims]
            bad = [i for i in dims if not 0 <= i < D or not np.isfinite(widths[i])]
            if bad:
                raise ValueError(f"distance dimensions {bad}: each must be one of 0-{D - 1} "
                                 f"with a finite width")
            self._measured = np.isin(np.arange(D), dims)
        self.observation_space = spaces.Box(-np.inf, np.inf, (D,), np.float64)

    def distance(self, state) -> float:
        """The state's distance to the target in cost widths."""
        z = (np.asarray(state, dtype=np.float64) - self.target)[self._measured]
        return float(np.sqrt(np.sum((z / self.widths[self._measured]) ** 2)))

    def _progress(self, info: dict) -> float:
        try:
            return float(info[self.progress_key])
        except (KeyError, TypeError, ValueError):
            raise ValueError(f"progress_key {self.progress_key!r}: the environment's info "
                             f"has no such number (its keys: {sorted(info)})") from None

    def _out(self, obs, info: dict):
        x = np.asarray(obs, dtype=np.float64).reshape(-1)[self._kept]
        if self.progress_key:
            left = self.progress_goal - (self._progress(info) - self._progress_start)
            return x, {**info, "distance": max(0.0, left)}
        return x, {**info, "distance": self.distance(x)}

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        if self.progress_key:
            self._progress_start = self._progress(info)
        return self._out(obs, info)

    def step(self, action):
        total = 0.0
        for _ in range(self.action_repeat):
            obs, reward, terminated, truncated, info = self.env.step(action)
            total += float(reward)
            if terminated or truncated:
                break
        x, info = self._out(obs, info)
        return x, total, bool(terminated), bool(truncated), info
