"""Gymnasium's Pendulum-v1 as a swing-up: :class:`PendulumSwingUp`.

The workload of the reference Python port's pendulum example: gymnasium's own pendulum
(``gymnasium.envs.classic_control.PendulumEnv``: a 1 m, 1 kg rod, torque in ±2 N m,
steps of 0.05 s, speed clipped to ±8 rad/s) started hanging down, and every action held
for ``substeps`` of its steps (3: 0.15 s per step of this env). The observation is
Pendulum-v1's ``[cos θ, sin θ, θ̇]`` (θ = 0 upright), the reward the sum of Pendulum-v1's
rewards over the sub-steps.
"""
from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np
from gymnasium.envs.classic_control.pendulum import PendulumEnv

from . import _checks as check
from .cartpole_draw import _Canvas

__all__ = ["PendulumSwingUp"]


def wrapped_angle(theta: float) -> float:
    """``theta`` [rad] in [-π, π) (0 upright)."""
    return float((theta + np.pi) % (2 * np.pi) - np.pi)


class PendulumSwingUp(gymnasium.Env):
    """Pendulum-v1 from hanging down, each action held for ``substeps`` steps.

    Args:
        render_mode: ``None`` or ``"rgb_array"`` (drawn with NumPy, no pygame).
        substeps: Pendulum-v1 steps per step (default 3).
        start_std: the start state is ``θ = π + start_std ε₁``, ``θ̇ = start_std ε₂``
            (ε standard normal; default 0.05), hanging down at rest up to that noise.
        max_episode_steps: the env's own horizon, or ``None`` (the registered id ends
            episodes with gymnasium's ``TimeLimit`` instead).
        render_width, render_height: size of rendered frames in pixels.

    ``info`` of ``reset`` and ``step``: ``"distance"`` (|θ| to upright [rad], θ in
    [-π, π)) and ``"theta"`` (θ [rad] in [-π, π)).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 7}

    def __init__(self, render_mode: str | None = None, *, substeps: int = 3,
                 start_std: float = 0.05, max_episode_steps: int | None = None,
                 render_width: int = 300, render_height: int = 300) -> None:
        super().__init__()
        self.render_mode = check.render_mode(render_mode, self.metadata["render_modes"])
        if isinstance(substeps, bool) or not isinstance(substeps, (int, np.integer)) \
                or substeps < 1:
            raise ValueError(f"substeps must be an int >= 1, got {substeps!r}")
        self.substeps = int(substeps)
        self.start_std = check.real(start_std, "start_std", allow_zero=True)
        self.max_episode_steps = check.horizon(max_episode_steps)
        self.render_width, self.render_height = check.render_size(render_width, render_height)
        self.pendulum = PendulumEnv()
        self.action_space = self.pendulum.action_space
        self.observation_space = self.pendulum.observation_space
        self._elapsed_steps = 0

    def _observe(self) -> tuple[np.ndarray, dict[str, Any]]:
        theta, theta_dot = self.pendulum.state
        obs = np.array([np.cos(theta), np.sin(theta), theta_dot], dtype=np.float32)
        angle = wrapped_angle(theta)
        return obs, {"distance": abs(angle), "theta": angle}

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Hang the pendulum down (with ``start_std`` noise); returns ``(obs [3], info)``."""
        seed = check.seed(seed)
        check.reset_options(options, ())  # checked before the seed is used
        super().reset(seed=seed)
        noise = self.start_std * self.np_random.standard_normal(2)
        self.pendulum.state = np.array([np.pi + noise[0], noise[1]])
        self.pendulum.last_u = None
        self._elapsed_steps = 0
        return self._observe()

    def step(self, action: Any):
        """Hold torque ``action`` [N m] (clipped to ±2) for ``substeps`` Pendulum-v1 steps."""
        if getattr(self.pendulum, "state", None) is None:
            raise RuntimeError("call reset() before step()")
        u = np.asarray(action, dtype=np.float32).reshape(-1)
        if u.shape != (1,) or not np.all(np.isfinite(u)):
            raise ValueError(f"action must be one finite torque, got {action!r}")
        reward = 0.0
        for _ in range(self.substeps):
            _, r, _, _, _ = self.pendulum.step(u)
            reward += float(r)
        self._elapsed_steps += 1
        truncated = (self.max_episode_steps is not None
                     and self._elapsed_steps >= self.max_episode_steps)
        obs, info = self._observe()
        return obs, reward, False, bool(truncated), info

    def render(self) -> np.ndarray | None:
        """The rod as an RGB image ``[height, width, 3]`` (``rgb_array`` mode), else None."""
        if self.render_mode is None:
            return None
        canvas = _Canvas(self.render_width, self.render_height)
        cx, cy = 0.5 * self.render_width, 0.5 * self.render_height
        scale = 0.4 * min(self.render_width, self.render_height)
        theta = float(self.pendulum.state[0])
        tip = (cx + scale * np.sin(theta), cy - scale * np.cos(theta))
        canvas.fill(canvas.disk(cx, cy - scale, 5.0) & ~canvas.disk(cx, cy - scale, 3.0),
                    (220, 30, 30))  # the upright target
        canvas.fill(canvas.segment((cx, cy), tip, max(4.0, 0.06 * scale)), (200, 130, 40))
        canvas.fill(canvas.disk(cx, cy, 4.0), (30, 30, 30))
        return canvas.img

    def close(self) -> None:
        self.pendulum.close()
