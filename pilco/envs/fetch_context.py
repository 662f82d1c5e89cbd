"""The Fetch reacher with its target in the observation: the context of a multi-task
policy, one policy for any target (:class:`TargetInState`)."""
from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np

__all__ = ["TargetInState"]


class TargetInState(gymnasium.ObservationWrapper):
    """Appends the target ``(3,)`` to the observation of a Fetch reacher env:
    ``(10,) -> (13,)``, ``[gripper xyz, 7 joint angles, target xyz]``. The target stays
    the same through an episode; ``reset(options={"target": t})`` moves it (the env keeps
    it for later episodes). The observation bounds of the target are those of the
    gripper position."""

    def __init__(self, env: gymnasium.Env) -> None:
        super().__init__(env)
        if not hasattr(env.unwrapped, "target") or not hasattr(env.unwrapped, "joint_dims"):
            raise TypeError(f"TargetInState needs a Fetch reacher env (with a target and "
                            f"joint_dims); got {type(env.unwrapped).__name__}")
        space = env.observation_space
        self.observation_space = gymnasium.spaces.Box(
            np.append(space.low, space.low[:3]), np.append(space.high, space.high[:3]),
            dtype=np.float64)

    def observation(self, observation: Any) -> np.ndarray:
        return np.append(np.asarray(observation, dtype=np.float64),
                         self.env.unwrapped.target)
