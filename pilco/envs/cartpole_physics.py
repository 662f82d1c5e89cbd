"""Cart-pole physics of the MATLAB PILCO release (``dynamics_cp.m``) and its cost.

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

The cost is the saturating ``1 - exp(-d^2 / (2 w^2))``, where ``d`` is the distance of the
pendulum tip ``(x + l sin th, -l cos th)`` to the upright target tip ``(0, l)``.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from scipy.integrate import solve_ivp

from pilco.envs import _checks as check

__all__ = ["CartPolePhysics"]

_STATE_LAYOUT = "[x, x_dot, theta_dot, theta]"


class CartPolePhysics:
    """Cart-pole dynamics, tip geometry and saturating cost, with a current :attr:`state`.

    The gymnasium environment :class:`pilco.envs.CartPoleSwingUp` builds on this class;
    the methods taking ``state=None`` use the current (noise-free) :attr:`state`.

    Args:
        cart_mass: ``M`` [kg], ``> 0``.
        pole_mass: ``m`` [kg], ``> 0``.
        pole_length: ``l`` [m], ``> 0``.
        friction: ``b`` [N/m/s], ``>= 0``.
        gravity: ``g`` [m/s^2], ``>= 0``.
        dt: control interval [s], ``> 0``.
        cost_width: width ``w`` of the saturating cost [m], ``> 0``.
        rtol, atol: tolerances of the ODE solver, ``> 0``.
    """

    #: Index of each state component.
    X, X_DOT, THETA_DOT, THETA = 0, 1, 2, 3

    def __init__(
        self,
        *,
        cart_mass: float,
        pole_mass: float,
        pole_length: float,
        friction: float,
        gravity: float,
        dt: float,
        cost_width: float,
        rtol: float,
        atol: float,
    ) -> None:
        self.cart_mass = check.real(cart_mass, "cart_mass", allow_zero=False)
        self.pole_mass = check.real(pole_mass, "pole_mass", allow_zero=False)
        self.pole_length = check.real(pole_length, "pole_length", allow_zero=False)
        self.friction = check.real(friction, "friction", allow_zero=True)
        self.gravity = check.real(gravity, "gravity", allow_zero=True)
        self.dt = check.real(dt, "dt", allow_zero=False)
        self.cost_width = check.real(cost_width, "cost_width", allow_zero=False)
        self.rtol = check.real(rtol, "rtol", allow_zero=False)
        self.atol = check.real(atol, "atol", allow_zero=False)
        self.state: np.ndarray | None = None

    @staticmethod
    def _as_state(value: Any, name: str) -> np.ndarray:
        """Convert ``value`` to a finite float64 array of shape ``(4,)``."""
        return check.vector(value, 4, name, layout=_STATE_LAYOUT)

    def _require_state(self) -> np.ndarray:
        if self.state is None:
            raise RuntimeError(f"{type(self).__name__}: call reset() before step()/render()")
        return self.state

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
        if duration is None:
            duration = self.dt
        duration = check.real(duration, "duration", allow_zero=False)
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
