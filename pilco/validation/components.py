"""The objects and functions given to the agent: controllers, rewards, squash functions.

A controller or reward is accepted when it follows its protocol
(:mod:`pilco.protocols`), whatever its class; the check also matches its dimensions with
the agent's state, policy input and actions.
"""
from __future__ import annotations

from typing import Optional, Sequence

from ..protocols import Controller, Reward

__all__ = ["check_squash", "check_callable", "check_reward", "check_reward_list",
           "check_controller"]


def check_squash(squash):
    """A squashing function ``(m, s, max_action) -> (M, S, C)`` or None, or a clear error."""
    if squash is not None and not callable(squash):
        raise TypeError(
            f"squash must be a function such as squash_sin or squash_sat (or None), got "
            f"{squash!r}"
        )
    return squash


def check_callable(value, name: str):
    """A function (any callable) or None, or a clear error."""
    if value is not None and not callable(value):
        raise TypeError(f"{name} must be callable, got {type(value).__name__}")
    return value


def _missing(obj, members: Sequence[str]) -> list:
    return [name for name in members if not callable(getattr(obj, name, None))]


def check_reward(reward, state_dim: Optional[int] = None, name: str = "reward"):
    """An object following :class:`pilco.protocols.Reward` (with ``state_dim`` if given)."""
    if (getattr(reward, "state_dim", None) is None or _missing(reward, ["moments"])
            or not isinstance(reward, Reward)):
        raise TypeError(
            f"{name} must be a reward (such as ExponentialReward) following "
            f"pilco.protocols.Reward: a state_dim attribute and a method moments(m, s), got "
            f"{type(reward).__name__}"
        )
    if state_dim is not None and reward.state_dim != state_dim:
        raise ValueError(f"{name}.state_dim is {reward.state_dim} but the state has "
                         f"dimension {state_dim}")
    return reward


def check_reward_list(rewards, state_dim: int, name: str = "rewards") -> list:
    """A non-empty list of rewards (:class:`pilco.protocols.Reward`) on a state of
    ``state_dim`` dimensions."""
    if not isinstance(rewards, (list, tuple)):
        raise TypeError(f"{name} must be a list of rewards, got {type(rewards).__name__}")
    if len(rewards) == 0:
        raise ValueError(f"{name} must not be empty")
    for i, r in enumerate(rewards):
        check_reward(r, name=f"{name}[{i}]")
        if r.state_dim != state_dim:
            raise ValueError(f"every reward must have state_dim {state_dim}, got "
                             f"{r.state_dim} for {type(r).__name__}")
    return list(rewards)


def check_controller(controller, feature_dim: int, control_dim: int, state_dim: int):
    """An object following :class:`pilco.protocols.Controller` that reads ``feature_dim``
    inputs (``state_dim`` plus one per angle) and returns ``control_dim`` actions."""
    if getattr(controller, "state_dim", None) is None:
        raise TypeError("controller must have a state_dim attribute (see "
                        "pilco.protocols.Controller)")
    missing = _missing(controller, ["prepare", "moments"])
    if not hasattr(controller, "trainable_variables"):
        missing.append("trainable_variables")
    if missing or not isinstance(controller, Controller):
        raise TypeError(
            f"controller must follow pilco.protocols.Controller (state_dim, control_dim, "
            f"trainable_variables, prepare() and moments(m, s, squash, prepared)); "
            f"{type(controller).__name__} lacks {', '.join(missing) or 'control_dim'}"
        )
    if controller.state_dim != feature_dim:
        raise ValueError(
            f"controller.state_dim is {controller.state_dim} but the policy input has "
            f"dimension {feature_dim} (state {state_dim} + one extra per angle in "
            f"angle_indices)"
        )
    if getattr(controller, "control_dim", None) != control_dim:
        raise ValueError(
            f"controller.control_dim is {getattr(controller, 'control_dim', None)} but the "
            f"data has {control_dim} action columns"
        )
    return controller
