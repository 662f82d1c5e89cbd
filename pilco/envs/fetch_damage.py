"""Damaged joints of the Fetch arm: which joints, how they fail, what they are forced to.

Modes (the agent is not told; the observation keeps its form, unless the env is wrapped
in :class:`DamageFlag`):

- ``"stuck"`` (the paper's unresponsive motor): the joints ignore every command and keep
  the angle they had when they broke: the start pose of each episode for an arm damaged
  from the start, the current angle for an arm damaged mid-run;
- ``"straight"``: a harder variant, the joints are forced to 0 rad at reset and at every
  step whatever the command (for the Fetch elbow a straightened arm, which starts about
  1.2 m from the paper's target and needs at least 13 steps of 0.1 rad to reach it, see
  :func:`pilco.envs.fewest_steps`).

``"zero"``, this mode's earlier name, is still accepted (runs saved with it resume).
"""
from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np

from pilco.envs import _checks as check
from pilco.envs.fetch_model import SHORT_NAMES, resolve_joints

__all__ = ["DAMAGE_MODES", "JointDamage", "DamageFlag", "damage_mode"]

DAMAGE_MODES = ("stuck", "straight")

#: earlier names of the modes, still accepted
_ALIASES = {"zero": "straight"}


def damage_mode(mode: Any) -> str:
    """``mode`` checked against :data:`DAMAGE_MODES` (earlier names mapped to today's);
    TypeError for a non-string, ValueError for an unknown mode."""
    if isinstance(mode, str) and mode in _ALIASES:
        return _ALIASES[mode]
    if mode == "zero_on_step":
        raise ValueError("damage_mode 'zero_on_step' was removed: the paper's final script "
                         "keeps the joint stuck at its start angle ('stuck'); 'straight' "
                         "forces it to 0 rad from the reset on")
    return check.choice(mode, "damage_mode", DAMAGE_MODES)


class JointDamage:
    """The damaged arm joints and the rule that overrides their commanded angles.

    Args:
        joints: joint name or names (short or full), none for a healthy arm.
        mode: one of :data:`DAMAGE_MODES`.
    """

    def __init__(self, joints: Any = (), mode: str = "stuck") -> None:
        self.joints: tuple[int, ...] = ()
        self.mode = "stuck"
        self._stuck = np.zeros(0)
        self.replace(joints, mode, np.zeros(len(SHORT_NAMES)))

    @property
    def names(self) -> tuple[str, ...]:
        """Short names of the damaged joints."""
        return tuple(SHORT_NAMES[i] for i in self.joints)

    def replace(self, joints: Any, mode: str, current: np.ndarray) -> None:
        """Damage ``joints`` instead of the previous ones; ``"stuck"`` joints hold their
        angles in ``current`` (7,)."""
        damaged = resolve_joints(joints)
        self.mode = damage_mode(mode)
        self.joints = damaged
        self._stuck = current[list(damaged)] if damaged else np.zeros(0)

    def clear(self) -> None:
        """Repair all joints."""
        self.joints = ()
        self._stuck = np.zeros(0)

    def _force(self, q: np.ndarray) -> np.ndarray:
        if self.joints:
            idx = list(self.joints)
            q[idx] = self._stuck if self.mode == "stuck" else 0.0
        return q

    def at_reset(self, q: np.ndarray) -> np.ndarray:
        """Angles ``q`` (7,) of a new episode's start pose after the damage (in place)."""
        if self.mode == "stuck" and self.joints:
            self._stuck = q[list(self.joints)].copy()
        return self._force(q)

    def at_step(self, q: np.ndarray) -> np.ndarray:
        """Commanded angles ``q`` (7,) of a step after the damage (in place)."""
        return self._force(q)


class DamageFlag(gymnasium.ObservationWrapper):
    """Appends 1.0 to the observation of a Fetch reacher env while any of its joints is
    damaged, 0.0 otherwise: observation ``(10,) -> (11,)``. It tells an agent when the
    arm broke, not which joint or how."""

    def __init__(self, env: gymnasium.Env) -> None:
        super().__init__(env)
        if not hasattr(env.unwrapped, "damaged_joints"):
            raise TypeError(f"DamageFlag needs a Fetch reacher env (with damaged_joints); "
                            f"got {type(env.unwrapped).__name__}")
        space = env.observation_space
        self.observation_space = gymnasium.spaces.Box(
            np.append(space.low, 0.0), np.append(space.high, 1.0), dtype=np.float64)

    def observation(self, observation: np.ndarray) -> np.ndarray:
        broken = bool(self.env.unwrapped.damaged_joints)
        return np.append(observation, 1.0 if broken else 0.0)
