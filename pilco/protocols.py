"""The public protocol of controllers and rewards: what :class:`pilco.models.PILCO` calls.

Any object with these members can be given to ``PILCO`` (no base class is needed);
:class:`pilco.controllers.LinearController`, :class:`pilco.controllers.RbfController` and
the rewards of :mod:`pilco.rewards` are implementations. Shapes: ``D`` the size of the
state the object reads, ``U`` the number of actions. All tensors are float64.

The methods are called inside a compiled TensorFlow function (the whole horizon is one
graph): write them with TensorFlow operations and keep parameters in ``gpflow.Parameter``
or ``tf.Variable`` objects, so the policy gradient reaches them.
"""
from __future__ import annotations

from typing import Any, Protocol, Tuple, runtime_checkable

__all__ = ["Controller", "Reward"]


@runtime_checkable
class Reward(Protocol):
    """A reward whose mean and variance under a Gaussian state are known in closed form.

    Attributes:
        state_dim: D, the size of the (raw) state the reward reads.
    """

    state_dim: int

    def moments(self, m, s) -> Tuple[Any, Any]:
        """Expected reward and its variance for x ~ N(m, s).

        Shapes: m [1, D], s [D, D] -> mean [1, 1], variance [1, 1].
        """

    # Optional, not part of the check: ``cost_geometry() ->
    # pilco.reward_geometry.CostGeometry`` (where the target is, in task units), which the
    # diagnosis reads for its distance and cost checks.


@runtime_checkable
class Controller(Protocol):
    """A policy ``u = pi(x)`` whose action moments under a Gaussian state are known.

    Attributes:
        state_dim: D, the size of the policy input (for ``PILCO``: the state with each
            angle replaced by its (sin, cos) pair).
        control_dim: U, the number of actions.
        trainable_variables: the variables ``PILCO.optimize_policy`` tunes (any
            ``tf.Module``, e.g. a ``gpflow.base.Module``, has them).

    ``optimize_policy(restarts > 1)`` also calls ``randomize(seed=...)`` to start each
    further run from new parameters; a controller without it allows one run.
    """

    state_dim: int
    control_dim: int

    @property
    def trainable_variables(self) -> Tuple[Any, ...]:
        """The trainable ``tf.Variable`` objects of the policy."""

    def prepare(self) -> Any:
        """Precompute whatever does not depend on the state (e.g. a kernel factorisation).

        Called once per evaluation of the policy objective; the result (any object,
        ``None`` if there is nothing to precompute) is handed back to every
        :meth:`moments` call of that rollout.
        """

    def moments(self, m, s, squash: bool = True, prepared: Any = None) -> Tuple[Any, Any, Any]:
        """Moments of the action for x ~ N(m, s).

        Shapes: m [1, D], s [D, D] -> M [1, U] mean, S [U, U] covariance,
        V [D, U] = inv(s) Cov[x, u] (the input-output covariance over the input's).
        ``squash=False`` returns the action before its bounds are applied;
        ``prepared`` is the result of :meth:`prepare` (computed here when ``None``).
        """
