"""Two cars and a crossing: :class:`TwoCarsCrossing`, the Safe PILCO paper's linear system.

Two cars drive along two roads that cross at position 0. The first car's acceleration is
the action (bounded by ``max_action``, default ±0.4 m/s²); the second car keeps its speed.
Per step of ``dt`` (0.5 s) the state ``[x1, v1, x2, v2]`` (positions [m], speeds [m/s])
moves as

    x1 += dt v1,   v1 += dt (u - friction v1) / mass,   x2 += dt v2,   v2 unchanged

from a start near ``(-6, 1, -5, 1)`` (each entry plus ``start_std`` times a standard
normal draw): the second car, one metre ahead, reaches the crossing first. The first car
should pass the crossing as soon as it can (reward +1 per step with ``x1 ≥ 0``, else -1)
without being in the crossing (``|x| ≤ half_width``, 1 m) while the second car is: that is
a collision, the constraint a safe policy keeps (``pilco.constraints.Region`` on
dimensions 0 and 2).

``info`` of ``reset`` and ``step``: ``"distance"``, how far the first car still is from the
crossing's far side (``max(0, half_width - x1)`` [m]: 0 once through), and
``"collision"``, whether both cars are in the crossing at this state.
"""
from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from . import _checks as check

__all__ = ["TwoCarsCrossing", "CROSSING_START"]

#: the mean start state ``[x1, v1, x2, v2]``
CROSSING_START = np.array([-6.0, 1.0, -5.0, 1.0])


class TwoCarsCrossing(gymnasium.Env):
    """Two cars approaching a crossing; the first car's acceleration is the action.

    Args:
        dt: seconds per step (0.5).
        mass, friction: the first car's mass [kg] and friction coefficient (1, 0.001).
        max_action: the acceleration bound [m/s²] (0.4).
        start_std: the std of the start state's noise per entry (0.03).
        half_width: the crossing covers ``[-half_width, half_width]`` on both roads (1 m).
        max_episode_steps: the env's own horizon, or ``None`` (the registered id ends
            episodes with gymnasium's ``TimeLimit`` instead, 25 steps).
        render_mode: ``None``: the cars are not drawn (gymnasium's argument, accepted so
            that ``gymnasium.make`` can pass it).
    """

    metadata = {"render_modes": []}

    def __init__(self, *, dt: float = 0.5, mass: float = 1.0, friction: float = 0.001,
                 max_action: float = 0.4, start_std: float = 0.03, half_width: float = 1.0,
                 max_episode_steps: int | None = None, render_mode: str | None = None) -> None:
        super().__init__()
        if render_mode is not None:
            raise ValueError(f"TwoCarsCrossing draws nothing: render_mode must be None, got "
                             f"{render_mode!r}")
        self.render_mode = None
        self.dt = check.real(dt, "dt", allow_zero=False)
        self.mass = check.real(mass, "mass", allow_zero=False)
        self.friction = check.real(friction, "friction", allow_zero=True)
        self.max_action = check.real(max_action, "max_action", allow_zero=False)
        self.start_std = check.real(start_std, "start_std", allow_zero=True)
        self.half_width = check.real(half_width, "half_width", allow_zero=False)
        self.max_episode_steps = check.horizon(max_episode_steps)
        self.action_space = spaces.Box(-self.max_action, self.max_action, (1,), np.float64)
        self.observation_space = spaces.Box(-np.inf, np.inf, (4,), np.float64)
        self.state: np.ndarray | None = None
        self._elapsed_steps = 0

    def _inside(self, x: float) -> bool:
        return abs(x) <= self.half_width

    def _observe(self) -> tuple[np.ndarray, dict[str, Any]]:
        x1, _, x2, _ = self.state
        info = {"distance": max(0.0, self.half_width - float(x1)),
                "collision": self._inside(x1) and self._inside(x2)}
        return self.state.copy(), info

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """The start state (with ``start_std`` noise); returns ``(state [4], info)``."""
        seed = check.seed(seed)
        check.reset_options(options, ())
        super().reset(seed=seed)
        self.state = CROSSING_START + self.start_std * self.np_random.standard_normal(4)
        self._elapsed_steps = 0
        return self._observe()

    def step(self, action: Any):
        """Accelerate the first car by ``action`` (clipped to ±``max_action``) for ``dt``."""
        if self.state is None:
            raise RuntimeError("call reset() before step()")
        u = np.asarray(action, dtype=np.float64).reshape(-1)
        if u.shape != (1,) or not np.all(np.isfinite(u)):
            raise ValueError(f"action must be one finite acceleration, got {action!r}")
        u = float(np.clip(u[0], -self.max_action, self.max_action))
        x1, v1, x2, v2 = self.state
        self.state = np.array([x1 + self.dt * v1,
                               v1 + self.dt * (u - self.friction * v1) / self.mass,
                               x2 + self.dt * v2, v2])
        self._elapsed_steps += 1
        truncated = (self.max_episode_steps is not None
                     and self._elapsed_steps >= self.max_episode_steps)
        obs, info = self._observe()
        reward = 1.0 if obs[0] >= 0.0 else -1.0
        return obs, reward, False, bool(truncated), info
