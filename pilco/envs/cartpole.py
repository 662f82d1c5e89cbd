"""Cart-pole swing-up of the MATLAB PILCO release (``settings_cp.m`` / ``dynamics_cp.m``).

The gymnasium environment :class:`CartPoleSwingUp`: start distribution, observation
noise, force clipping, horizon and rendering around the physics of
:class:`pilco.envs.cartpole_physics.CartPolePhysics` (state ``[x, x_dot, theta_dot,
theta]``, ``theta = 0`` hanging down, target upright ``theta = pi``; the equations of
motion are written there).

Reward is the negative saturating cost ``1 - exp(-d^2 / (2 w^2))`` with ``w = 0.25`` m,
where ``d`` is the distance of the pendulum tip ``(x + l sin th, -l cos th)`` to the
upright target tip ``(0, l)``.
"""
from __future__ import annotations

import logging
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from pilco.envs import _checks as check
from pilco.envs.cartpole_draw import draw_cartpole
from pilco.envs.cartpole_physics import CartPolePhysics

logger = logging.getLogger(__name__)

__all__ = ["CartPoleSwingUp"]


class CartPoleSwingUp(CartPolePhysics, gymnasium.Env):
    """Cart-pole swing-up task of the MATLAB PILCO release.

    Observation: noisy state ``[x, x_dot, theta_dot, theta]``, shape ``(4,)``, float64
    (Gaussian measurement noise of std ``noise_std`` is added to the returned
    observation only; the internal :attr:`state` is noise free).

    Action: horizontal force on the cart, shape ``(1,)``, in ``[-max_force, max_force]`` N;
    out-of-range actions are clipped.

    Reward: ``-(1 - exp(-d^2 / (2 cost_width^2)))`` computed from the true state, where
    ``d`` is the tip-to-target distance (see :meth:`tip_distance`). Always in ``[-1, 0]``.

    Episodes never terminate (``terminated`` is always ``False``); ``truncated`` becomes
    ``True`` after ``max_episode_steps`` steps (``None`` disables the internal limit, e.g.
    when a :class:`gymnasium.wrappers.TimeLimit` does the job).

    Args:
        render_mode: ``None`` or ``"rgb_array"``.
        cart_mass: ``M`` [kg] (default 0.5).
        pole_mass: ``m`` [kg] (default 0.5).
        pole_length: ``l`` [m] (default 0.5).
        friction: ``b`` [N/m/s] (default 0.1).
        gravity: ``g`` [m/s^2] (default 9.82).
        dt: control interval [s] (default 0.1).
        max_force: force bound [N] (default 10).
        noise_std: std of the observation noise (default 0.01; 0 disables it).
        start_mean: mean of the start state, shape ``(4,)`` (default zeros: hanging down).
        start_std: std of the start state, scalar or shape ``(4,)`` (default 0.1).
        max_episode_steps: horizon (default 40 steps = 4 s) or ``None``.
        cost_width: width ``w`` of the saturating cost [m] (default 0.25).
        render_width: width of rendered frames in pixels (default 600).
        render_height: height of rendered frames in pixels (default 400).
        rtol: relative tolerance of the ODE solver (default 1e-8).
        atol: absolute tolerance of the ODE solver (default 1e-10).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self,
        render_mode: str | None = None,
        *,
        cart_mass: float = 0.5,
        pole_mass: float = 0.5,
        pole_length: float = 0.5,
        friction: float = 0.1,
        gravity: float = 9.82,
        dt: float = 0.1,
        max_force: float = 10.0,
        noise_std: float = 0.01,
        start_mean: Any = None,
        start_std: Any = 0.1,
        max_episode_steps: int | None = 40,
        cost_width: float = 0.25,
        render_width: int = 600,
        render_height: int = 400,
        rtol: float = 1e-8,
        atol: float = 1e-10,
    ) -> None:
        gymnasium.Env.__init__(self)
        self.render_mode = check.render_mode(render_mode, self.metadata["render_modes"])
        CartPolePhysics.__init__(
            self,
            cart_mass=cart_mass,
            pole_mass=pole_mass,
            pole_length=pole_length,
            friction=friction,
            gravity=gravity,
            dt=dt,
            cost_width=cost_width,
            rtol=rtol,
            atol=atol,
        )
        self.max_force = check.real(max_force, "max_force", allow_zero=False)
        self.noise_std = check.real(noise_std, "noise_std", allow_zero=True)
        self.start_mean = self._as_state(np.zeros(4) if start_mean is None else start_mean,
                                         "start_mean")
        self.start_std = check.std(start_std, 4, "start_std")
        self.max_episode_steps = check.horizon(max_episode_steps)
        self.render_width, self.render_height = check.render_size(render_width, render_height)

        self.action_space = spaces.Box(
            low=-self.max_force, high=self.max_force, shape=(1,), dtype=np.float64
        )
        self.observation_space = spaces.Box(low=-np.inf, high=np.inf, shape=(4,), dtype=np.float64)

        self._elapsed_steps = 0
        self._last_force = 0.0

    def _as_force(self, action: Any) -> float:
        """Validate an action (scalar or shape ``(1,)``) and return the clipped force."""
        try:
            arr = np.asarray(action, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise TypeError(f"action must be a number or array of shape (1,): {exc}") from exc
        if arr.size != 1 or arr.ndim > 1:
            raise ValueError(f"action must be a scalar or have shape (1,), got shape {arr.shape}")
        force = float(arr.reshape(()))
        if not np.isfinite(force):
            raise ValueError(f"action must be finite, got {force}")
        clipped = float(np.clip(force, -self.max_force, self.max_force))
        if clipped != force:
            logger.debug("Clipped force %.4g N to %.4g N", force, clipped)
        return clipped

    # ------------------------------------------------------------- gym API
    def _observe(self) -> np.ndarray:
        state = self._require_state()
        if self.noise_std > 0:
            return state + self.noise_std * self.np_random.standard_normal(4)
        return state.copy()

    def _info(self) -> dict[str, Any]:
        return {"tip_distance": self.tip_distance(), "state": self.state.copy()}

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start a new episode.

        Args:
            seed: seeds ``self.np_random`` (start state and observation noise).
            options: optional ``{"state": array of shape (4,)}`` to set an exact start state.

        Returns:
            ``(observation of shape (4,), info)``; ``info["tip_distance"]`` and
            ``info["state"]`` (true state, shape ``(4,)``).
        """
        # every argument is checked before anything changes (the seed included)
        seed = check.seed(seed)
        options = check.reset_options(options, ("state",))
        state = (self._as_state(options["state"], "options['state']") if "state" in options
                 else None)
        super().reset(seed=seed)
        if state is not None:
            self.state = state
        else:
            self.state = self.start_mean + self.start_std * self.np_random.standard_normal(4)
        self._elapsed_steps = 0
        self._last_force = 0.0
        return self._observe(), self._info()

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Apply a force for ``dt`` seconds.

        Args:
            action: force [N], scalar or shape ``(1,)``; clipped to ``[-max_force, max_force]``.

        Returns:
            ``(observation (4,), reward, terminated=False, truncated, info)``; ``info`` has
            ``"tip_distance"``, ``"state"`` (true state, ``(4,)``) and ``"force"`` (applied).
        """
        state = self._require_state()
        force = self._as_force(action)
        self.state = self.integrate(state, force)
        self._last_force = force
        self._elapsed_steps += 1
        reward = -self.cost()
        truncated = (
            self.max_episode_steps is not None and self._elapsed_steps >= self.max_episode_steps
        )
        info = self._info()
        info["force"] = force
        return self._observe(), reward, False, bool(truncated), info

    # --------------------------------------------------------------- render
    def render(self) -> np.ndarray | None:
        """Draw the current state.

        Returns:
            ``uint8`` image of shape ``(render_height, render_width, 3)`` in
            ``"rgb_array"`` mode, else ``None``.
        """
        if self.render_mode is None:
            logger.warning(
                "CartPoleSwingUp.render() called without a render_mode; "
                "construct with render_mode='rgb_array'"
            )
            return None
        return self._draw(self._require_state())

    def _draw(self, state: np.ndarray) -> np.ndarray:
        """Rasterise the scene for ``state`` (4,) with NumPy."""
        return draw_cartpole(
            state[self.X],
            self.tip_position(state),
            self.target_tip_position,
            self.pole_length,
            self.render_width,
            self.render_height,
        )

    def close(self) -> None:
        """Nothing to release (no windows or GL contexts)."""
        return None
