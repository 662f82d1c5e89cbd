"""Cart-pole swing-up of the MATLAB PILCO release (``settings_cp.m`` / ``dynamics_cp.m``).

State ``[x, x_dot, theta_dot, theta]`` (shape ``(4,)``):

- ``x``: cart position [m], ``x_dot``: cart velocity [m/s],
- ``theta_dot``: pendulum angular velocity [rad/s],
- ``theta``: pendulum angle [rad]; ``theta = 0`` hangs DOWN, the target is upright ``theta = pi``.

Equations of motion with cart mass ``M``, pendulum mass ``m``, pendulum length ``l``,
friction ``b``, gravity ``g`` and horizontal force ``f`` on the cart::

    xdd  = (2 m l thd^2 sin th + 3 m g sin th cos th + 4 f - 4 b xd)
           / (4 (M + m) - 3 m cos^2 th)
    thdd = (-3 m l thd^2 sin th cos th - 6 (M + m) g sin th - 6 (f - b xd) cos th)
           / (4 l (m + M) - 3 m l cos^2 th)

The force is held constant over each control interval ``dt`` (zero-order hold) and the
ODE is integrated with :func:`scipy.integrate.solve_ivp` (RK45).

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
from scipy.integrate import solve_ivp

logger = logging.getLogger(__name__)

__all__ = ["CartPoleSwingUp"]


def _positive_float(name: str, value: Any, *, allow_zero: bool = False) -> float:
    """Validate a scalar physical constant and return it as ``float``."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
    value = float(value)
    if not np.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value}")
    if value < 0 or (value == 0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name} must be {bound}, got {value}")
    return value


class CartPoleSwingUp(gymnasium.Env):
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

    #: Index of each state component.
    X, X_DOT, THETA_DOT, THETA = 0, 1, 2, 3

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
        super().__init__()
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode must be None or one of {self.metadata['render_modes']}, "
                f"got {render_mode!r}"
            )
        self.render_mode = render_mode

        self.cart_mass = _positive_float("cart_mass", cart_mass)
        self.pole_mass = _positive_float("pole_mass", pole_mass)
        self.pole_length = _positive_float("pole_length", pole_length)
        self.friction = _positive_float("friction", friction, allow_zero=True)
        self.gravity = _positive_float("gravity", gravity, allow_zero=True)
        self.dt = _positive_float("dt", dt)
        self.max_force = _positive_float("max_force", max_force)
        self.noise_std = _positive_float("noise_std", noise_std, allow_zero=True)
        self.cost_width = _positive_float("cost_width", cost_width)
        self.rtol = _positive_float("rtol", rtol)
        self.atol = _positive_float("atol", atol)

        if start_mean is None:
            start_mean = np.zeros(4)
        self.start_mean = self._as_state(start_mean, "start_mean")
        try:
            start_std_arr = np.asarray(start_std, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise TypeError(f"start_std must be a number or array of shape (4,): {exc}") from exc
        if start_std_arr.shape not in ((), (1,), (4,)):
            raise ValueError(
                f"start_std must be a scalar or have shape (4,), got shape {start_std_arr.shape}"
            )
        start_std_arr = np.broadcast_to(start_std_arr, (4,)).copy()
        if not np.all(np.isfinite(start_std_arr)) or np.any(start_std_arr < 0):
            raise ValueError(f"start_std must be finite and >= 0, got {start_std_arr}")
        self.start_std = start_std_arr

        if max_episode_steps is not None:
            if isinstance(max_episode_steps, bool) or not isinstance(
                max_episode_steps, (int, np.integer)
            ):
                raise TypeError(
                    f"max_episode_steps must be an int or None, got {type(max_episode_steps).__name__}"
                )
            if max_episode_steps <= 0:
                raise ValueError(f"max_episode_steps must be > 0, got {max_episode_steps}")
            max_episode_steps = int(max_episode_steps)
        self.max_episode_steps = max_episode_steps

        for name, value in (("render_width", render_width), ("render_height", render_height)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise TypeError(f"{name} must be an int, got {type(value).__name__}")
            if value < 16:
                raise ValueError(f"{name} must be >= 16 pixels, got {value}")
        self.render_width = int(render_width)
        self.render_height = int(render_height)

        self.action_space = spaces.Box(
            low=-self.max_force, high=self.max_force, shape=(1,), dtype=np.float64
        )
        self.observation_space = spaces.Box(low=-np.inf, high=np.inf, shape=(4,), dtype=np.float64)

        self.state: np.ndarray | None = None
        self._elapsed_steps = 0
        self._last_force = 0.0

    # ------------------------------------------------------------------ helpers
    @staticmethod
    def _as_state(value: Any, name: str) -> np.ndarray:
        """Convert ``value`` to a finite float64 array of shape ``(4,)``."""
        try:
            arr = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise TypeError(f"{name} must be array-like of 4 numbers: {exc}") from exc
        if arr.shape != (4,):
            raise ValueError(
                f"{name} must have shape (4,) = [x, x_dot, theta_dot, theta], got {arr.shape}"
            )
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} must be finite, got {arr}")
        return arr.copy()

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

    # ---------------------------------------------------------------- dynamics
    def state_derivative(self, state: Any, force: float) -> np.ndarray:
        """Time derivative of the state under a constant force.

        Args:
            state: ``[x, x_dot, theta_dot, theta]``, shape ``(4,)``.
            force: horizontal force on the cart [N] (not clipped here).

        Returns:
            ``[x_dot, x_ddot, theta_ddot, theta_dot]``, shape ``(4,)``.
        """
        _, x_dot, theta_dot, theta = np.asarray(state, dtype=np.float64).reshape(4)
        big_m, m, l, b, g = (
            self.cart_mass,
            self.pole_mass,
            self.pole_length,
            self.friction,
            self.gravity,
        )
        s, c = np.sin(theta), np.cos(theta)
        x_ddot = (
            2.0 * m * l * theta_dot**2 * s + 3.0 * m * g * s * c + 4.0 * force - 4.0 * b * x_dot
        ) / (4.0 * (big_m + m) - 3.0 * m * c**2)
        theta_ddot = (
            -3.0 * m * l * theta_dot**2 * s * c
            - 6.0 * (big_m + m) * g * s
            - 6.0 * (force - b * x_dot) * c
        ) / (4.0 * l * (m + big_m) - 3.0 * m * l * c**2)
        return np.array([x_dot, x_ddot, theta_ddot, theta_dot])

    def integrate(self, state: Any, force: float, duration: float | None = None) -> np.ndarray:
        """Integrate the dynamics from ``state`` holding ``force`` constant.

        Args:
            state: start state, shape ``(4,)``.
            force: constant force [N] over the interval (not clipped here).
            duration: interval length [s]; defaults to ``dt``.

        Returns:
            State after ``duration`` seconds, shape ``(4,)``.
        """
        y0 = self._as_state(state, "state")
        duration = self.dt if duration is None else _positive_float("duration", duration)
        sol = solve_ivp(
            lambda _t, y: self.state_derivative(y, force),
            (0.0, duration),
            y0,
            method="RK45",
            rtol=self.rtol,
            atol=self.atol,
        )
        if not sol.success:  # pragma: no cover - RK45 on this smooth ODE does not fail
            raise RuntimeError(f"ODE integration failed: {sol.message}")
        return sol.y[:, -1].copy()

    # -------------------------------------------------------------------- cost
    def tip_position(self, state: Any = None) -> np.ndarray:
        """Pendulum tip position ``(x + l sin theta, -l cos theta)``, shape ``(2,)``.

        Args:
            state: shape ``(4,)``; the true internal state if ``None``.
        """
        state = self._require_state() if state is None else self._as_state(state, "state")
        x, theta = state[self.X], state[self.THETA]
        return np.array([x + self.pole_length * np.sin(theta), -self.pole_length * np.cos(theta)])

    @property
    def target_tip_position(self) -> np.ndarray:
        """Upright target tip position ``(0, l)``, shape ``(2,)``."""
        return np.array([0.0, self.pole_length])

    def tip_distance(self, state: Any = None) -> float:
        """Euclidean distance of the pendulum tip to the upright target tip ``(0, l)``.

        Args:
            state: shape ``(4,)``; the true internal state if ``None``.

        Returns:
            Distance in metres (a Python float).
        """
        return float(np.linalg.norm(self.tip_position(state) - self.target_tip_position))

    def cost(self, state: Any = None) -> float:
        """Saturating cost ``1 - exp(-d^2 / (2 cost_width^2))`` in ``[0, 1]``.

        Args:
            state: shape ``(4,)``; the true internal state if ``None``.
        """
        d = self.tip_distance(state)
        return float(1.0 - np.exp(-(d**2) / (2.0 * self.cost_width**2)))

    # ------------------------------------------------------------- gym API
    def _require_state(self) -> np.ndarray:
        if self.state is None:
            raise RuntimeError("CartPoleSwingUp: call reset() before step()/render()")
        return self.state

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
        super().reset(seed=seed)
        if options is not None and not isinstance(options, dict):
            raise TypeError(f"options must be a dict or None, got {type(options).__name__}")
        options = options or {}
        unknown = set(options) - {"state"}
        if unknown:
            raise ValueError(f"Unknown reset options {sorted(unknown)}; valid: ['state']")
        if "state" in options:
            self.state = self._as_state(options["state"], "options['state']")
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
        """Rasterise the scene with NumPy (no OpenGL, no matplotlib)."""
        h, w = self.render_height, self.render_width
        view_width = max(4.0, 8.0 * self.pole_length)  # metres visible horizontally
        scale = w / view_width  # pixels per metre
        cy = 0.5 * h  # rail row
        cx = 0.5 * w  # x = 0 column

        def to_px(xw: float, yw: float) -> tuple[float, float]:
            return cx + xw * scale, cy - yw * scale

        cols = np.arange(w, dtype=np.float64)[None, :] + 0.5
        rows = np.arange(h, dtype=np.float64)[:, None] + 0.5
        img = np.full((h, w, 3), 250, dtype=np.uint8)

        def fill(mask: np.ndarray, color: tuple[int, int, int]) -> None:
            img[np.broadcast_to(mask, (h, w))] = color

        def disk(px: float, py: float, radius: float) -> np.ndarray:
            return (cols - px) ** 2 + (rows - py) ** 2 <= radius**2

        def segment(p0: tuple[float, float], p1: tuple[float, float], width: float) -> np.ndarray:
            ax, ay = p0
            dx, dy = p1[0] - ax, p1[1] - ay
            length2 = dx * dx + dy * dy
            if length2 == 0.0:
                return disk(ax, ay, width / 2)
            t = np.clip(((cols - ax) * dx + (rows - ay) * dy) / length2, 0.0, 1.0)
            return (cols - ax - t * dx) ** 2 + (rows - ay - t * dy) ** 2 <= (width / 2) ** 2

        # Rail and tick marks every metre.
        fill(np.abs(rows - cy) <= 1.0, (120, 120, 120))
        for xm in np.arange(np.ceil(-view_width / 2), np.floor(view_width / 2) + 1):
            px, _ = to_px(xm, 0.0)
            fill((np.abs(cols - px) <= 0.75) & (np.abs(rows - cy - 6) <= 5), (120, 120, 120))

        # Target tip marker: red ring with a cross.
        tx, ty = to_px(*self.target_tip_position)
        r_t = max(4.0, 0.06 * scale)
        ring = disk(tx, ty, r_t) & ~disk(tx, ty, r_t - 2.5)
        fill(ring, (220, 30, 30))
        fill(segment((tx - r_t, ty), (tx + r_t, ty), 1.5), (220, 30, 30))
        fill(segment((tx, ty - r_t), (tx, ty + r_t), 1.5), (220, 30, 30))

        # Cart.
        x = float(state[self.X])
        cart_w, cart_h = 0.4 * scale, 0.2 * scale
        px, py = to_px(x, 0.0)
        cart = (np.abs(cols - px) <= cart_w / 2) & (np.abs(rows - py) <= cart_h / 2)
        fill(cart, (40, 90, 200))

        # Pole and tip.
        tip = to_px(*self.tip_position(state))
        pole_w = max(3.0, 0.04 * scale)
        fill(segment((px, py), tip, pole_w), (200, 130, 40))
        fill(disk(px, py, pole_w * 0.8), (30, 30, 30))
        fill(disk(tip[0], tip[1], pole_w), (110, 60, 10))
        return img

    def close(self) -> None:
        """Nothing to release (no windows or GL contexts)."""
        return None
