"""Joint-space reacher on the 7-DoF Fetch arm (the PILCO paper's robot task).

Unlike gymnasium-robotics' ``FetchReach`` (4-D end-effector action, physics steps), this
environment drives the seven arm joints directly: an action is a relative rotation of
each joint, the new joint angles are written into ``qpos`` and MuJoCo forward kinematics
(``mujoco.mj_forward``, no physics step) gives the gripper position. The MuJoCo side
(model, limits, kinematics, rendering) is :mod:`pilco.envs.fetch_model`, damaged joints
are :mod:`pilco.envs.fetch_damage`.

``mujoco`` is imported lazily (on construction), so importing this module does not need
mujoco or gymnasium-robotics.
"""
from __future__ import annotations

import logging
from collections.abc import Mapping
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from pilco.envs import _checks as check
from pilco.envs.fetch_damage import DAMAGE_MODES, JointDamage  # noqa: F401 - re-exported
from pilco.envs.fetch_model import (  # noqa: F401 - the constants stay importable from here
    ARM_JOINTS,
    DEFAULT_CAMERA,
    DEFAULT_FIXED_QPOS,
    GRIP_SITE,
    SHORT_NAMES,
    TARGET_SITE,
    FetchArm,
    default_model_path,
    resolve_joint,
)

logger = logging.getLogger(__name__)

__all__ = [
    "ARM_JOINTS",
    "DEFAULT_START_QPOS",
    "DEFAULT_TARGET",
    "DEFAULT_FIXED_QPOS",
    "FetchJointReacher",
    "default_model_path",
]

#: Default start joint angles [rad], shape ``(7,)``.
DEFAULT_START_QPOS: tuple[float, ...] = (0.0, -1.0, 0.0, 2.0, 0.0, 0.5, 0.0)

#: Default target of the gripper [m], shape ``(3,)``.
DEFAULT_TARGET: tuple[float, float, float] = (1.2, 0.38, 0.38)

#: What the observation's joint part holds (``joint_state`` argument).
JOINT_STATES = ("measured", "commanded")


class FetchJointReacher(gymnasium.Env):
    """Reach a 3-D target with the Fetch arm's gripper by rotating its seven joints.

    Observation, shape ``(10,)`` float64: gripper (``robot0:grip`` site) position xyz [m]
    and 7 joint angles [rad] (:data:`ARM_JOINTS` order): the arm's actual angles with
    ``joint_state="measured"``; with ``"commanded"`` (the published scripts' state) the
    episode's start angles plus the running sum of the clipped actions, not limited (the
    arm follows them within its joint limits and its damage).

    Action, shape ``(7,)``: relative rotation of each joint [rad], clipped to
    ``[-max_action, max_action]`` (default 0.1); the arm's new angles are clipped to the
    model's joint limits (``jnt_range``; the three roll joints are unlimited).

    Reward: ``-||ee - target||`` of the real gripper. ``terminated`` when the distance is
    below ``distance_threshold``; ``truncated`` after ``max_episode_steps`` steps
    (``None`` disables the internal limit). ``info = {"distance", "is_success",
    "ee_position", "qpos"}`` (``qpos``: the arm's actual angles).

    Damage (the agent is not told; it persists across resets until :meth:`repair`):
    ``damaged_joints`` with ``damage_mode`` ``"stuck"`` (the paper's: they ignore commands
    and hold the angle where the damage found them, the start pose at each reset) or
    ``"straight"`` (0 rad at reset and every step); see :mod:`pilco.envs.fetch_damage`.

    Args:
        render_mode: ``None`` or ``"rgb_array"`` (offscreen ``mujoco.Renderer``).
        start_qpos: start joint angles, shape ``(7,)`` (default
            ``[0, -1, 0, 2, 0, 0.5, 0]``, gripper at about ``(1.228, 0.744, 0.488)`` m).
        target: gripper target, shape ``(3,)`` (default ``(1.2, 0.38, 0.38)`` m).
        start_noise: std [rad] of Gaussian noise added to ``start_qpos`` at reset.
        max_action: bound of the per-step joint rotation [rad].
        distance_threshold: success radius [m].
        max_episode_steps: horizon (default 50) or ``None``.
        damaged_joints: names of damaged joints (default none).
        damage_mode: ``"stuck"`` or ``"straight"``.
        joint_state: ``"measured"`` or ``"commanded"`` joint angles in the observation.
        fixed_qpos: overrides of :data:`DEFAULT_FIXED_QPOS` (base slides, torso, head,
            fingers), ``{joint name: value}``.
        model_path: MJCF file; defaults to gymnasium-robotics' ``fetch/reach.xml``.
        render_width, render_height: frame size in pixels (at most 640 x 480, the
            model's offscreen buffer).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self,
        render_mode: str | None = None,
        *,
        start_qpos: Any = DEFAULT_START_QPOS,
        target: Any = DEFAULT_TARGET,
        start_noise: float = 0.0,
        max_action: float = 0.1,
        distance_threshold: float = 0.05,
        max_episode_steps: int | None = 50,
        damaged_joints: Any = (),
        damage_mode: str = "stuck",
        joint_state: str = "measured",
        fixed_qpos: Mapping[str, float] | None = None,
        model_path: str | None = None,
        render_width: int = 640,
        render_height: int = 480,
    ) -> None:
        super().__init__()
        self.render_mode = check.render_mode(render_mode, self.metadata["render_modes"])
        self._start_qpos = check.vector(start_qpos, 7, "start_qpos")
        target = check.vector(target, 3, "target")
        self.start_noise = check.real(start_noise, "start_noise", allow_zero=True)
        self.max_action = check.real(max_action, "max_action", allow_zero=False)
        self.distance_threshold = check.real(distance_threshold, "distance_threshold",
                                             allow_zero=True)
        self.max_episode_steps = check.horizon(max_episode_steps)
        self._damage = JointDamage(damaged_joints, damage_mode)
        self.joint_state = check.choice(joint_state, "joint_state", JOINT_STATES)
        self.render_width, self.render_height = check.render_size(render_width, render_height)

        self._arm = FetchArm(model_path, fixed_qpos, target)
        self._arm.check_frame_size(self.render_width, self.render_height)
        self.model_path, self.model, self.data = (
            self._arm.model_path, self._arm.model, self._arm.data
        )
        self._lower, self._upper = self._arm.lower, self._arm.upper

        self.action_space = spaces.Box(
            low=-self.max_action, high=self.max_action, shape=(7,), dtype=np.float64
        )
        self.observation_space = spaces.Box(low=-np.inf, high=np.inf, shape=(10,), dtype=np.float64)
        self._elapsed_steps = 0
        self._ready = False
        # Put the arm in its start pose so ee_position etc. are meaningful before reset().
        self._arm.set_qpos(self._start_qpos.copy())
        self._commanded = self._arm.qpos

    # --------------------------------------------------------------- properties
    @property
    def joint_names(self) -> tuple[str, ...]:
        """Full names of the arm joints, action/observation order."""
        return ARM_JOINTS

    @property
    def joint_dims(self) -> tuple[int, ...]:
        """Observation index of each joint's angle, action order: ``(3, ..., 9)``."""
        return tuple(range(3, 3 + len(ARM_JOINTS)))

    @property
    def joint_limits(self) -> np.ndarray:
        """Joint limits ``[[low, high], ...]`` [rad], shape ``(7, 2)``; ±inf if unlimited."""
        return np.stack([self._lower, self._upper], axis=1)

    @property
    def qpos(self) -> np.ndarray:
        """Current (measured) arm joint angles [rad], shape ``(7,)`` (a copy)."""
        return self._arm.qpos

    @property
    def commanded_qpos(self) -> np.ndarray:
        """Start angles plus the clipped actions so far [rad], shape ``(7,)`` (a copy)."""
        return self._commanded.copy()

    @property
    def ee_position(self) -> np.ndarray:
        """Current gripper (``robot0:grip`` site) position [m], shape ``(3,)`` (a copy)."""
        return self._arm.ee_position

    @property
    def target(self) -> np.ndarray:
        """Target position [m], shape ``(3,)`` (a copy)."""
        return self._arm.target.copy()

    @target.setter
    def target(self, value: Any) -> None:
        self._arm.target = check.vector(value, 3, "target")
        self._arm.update_marker()

    @property
    def start_qpos(self) -> np.ndarray:
        """Start joint angles [rad], shape ``(7,)`` (a copy)."""
        return self._start_qpos.copy()

    @start_qpos.setter
    def start_qpos(self, value: Any) -> None:
        self._start_qpos = check.vector(value, 7, "start_qpos")

    @property
    def damaged_joints(self) -> tuple[str, ...]:
        """Short names of the damaged joints."""
        return self._damage.names

    @property
    def damage_mode(self) -> str:
        """``"stuck"`` or ``"straight"``."""
        return self._damage.mode

    def forward_kinematics(self, qpos: Any) -> np.ndarray:
        """Gripper position for arm angles ``qpos`` (7,), shape ``(3,)``; the env's
        current pose is restored afterwards. Joint limits and damage are NOT applied."""
        return self._arm.forward_kinematics(qpos)

    def distance(self) -> float:
        """Distance [m] of the gripper to the target."""
        return float(np.linalg.norm(self.ee_position - self._arm.target))

    # ----------------------------------------------------------------- damage
    def damage(self, joints: Any = ("elbow_flex",), mode: str = "stuck") -> None:
        """Damage ``joints`` (name or names, short or full) of a running env, replacing
        any previous damage. ``mode`` ``"stuck"``: held where they are now (and at the
        start pose after a reset); ``"straight"``: forced to 0 rad from the next step on.
        """
        self._damage.replace(joints, mode, self.qpos)
        logger.info("Damaged Fetch joints %s (mode %s)", self.damaged_joints, mode)

    def repair(self) -> None:
        """Remove all damage (the joints respond to commands again from the next step)."""
        self._damage.clear()
        logger.info("Repaired all Fetch joints")

    # ---------------------------------------------------------------- gym API
    def _obs(self) -> np.ndarray:
        joints = self._commanded if self.joint_state == "commanded" else self.qpos
        return np.concatenate([self.ee_position, joints])

    def _info(self) -> dict[str, Any]:
        d = self.distance()
        return {"distance": d, "is_success": bool(d < self.distance_threshold),
                "ee_position": self.ee_position, "qpos": self.qpos}

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Put the arm in the start pose (plus ``start_noise``, within the joint limits).

        Args:
            seed: ``None`` or an int ``>= 0``; seeds ``self.np_random``.
            options: optional ``{"qpos": (7,) start angles for this episode,
                "target": (3,) new target (kept for later episodes)}``.

        Returns:
            ``(observation (10,), info)``.
        """
        # every argument is checked before anything changes (the seed, the target)
        seed = check.seed(seed)
        options = check.reset_options(options, ("qpos", "target"))
        target = (check.vector(options["target"], 3, "options['target']")
                  if "target" in options else None)
        q = (check.vector(options["qpos"], 7, "options['qpos']") if "qpos" in options
             else self.start_qpos)
        super().reset(seed=seed)
        if target is not None:
            self._arm.target = target
        if self.start_noise > 0:
            q = q + self.start_noise * self.np_random.standard_normal(7)
        q = np.clip(q, self._lower, self._upper)
        self._commanded = q.copy()
        self._arm.set_qpos(self._damage.at_reset(q))
        self._elapsed_steps = 0
        self._ready = True
        return self._obs(), self._info()

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Rotate the joints by ``action`` (7,) [rad] (clipped), then forward kinematics.

        Returns:
            ``(observation (10,), reward = -distance, terminated, truncated, info)``.
        """
        if not self._ready:
            raise RuntimeError("FetchJointReacher: call reset() before step()")
        a = np.clip(check.vector(action, 7, "action"), -self.max_action, self.max_action)
        self._commanded = self._commanded + a
        base = self._commanded if self.joint_state == "commanded" else self.qpos + a
        q = np.clip(base, self._lower, self._upper)
        self._arm.set_qpos(self._damage.at_step(q))
        self._elapsed_steps += 1
        info = self._info()
        terminated = info["is_success"]
        truncated = (
            self.max_episode_steps is not None and self._elapsed_steps >= self.max_episode_steps
        )
        return self._obs(), -info["distance"], terminated, bool(truncated), info

    # ----------------------------------------------------------------- render
    def render(self) -> np.ndarray | None:
        """Offscreen frame, ``uint8`` of shape ``(render_height, render_width, 3)`` in
        ``"rgb_array"`` mode (the target is the red sphere), else ``None``.

        Refuses (``RuntimeError``) in a process that imported TensorFlow, see
        :meth:`pilco.envs.fetch_model.FetchArm.render`.
        """
        if self.render_mode is None:
            logger.warning(
                "FetchJointReacher.render() called without a render_mode; "
                "construct with render_mode='rgb_array'"
            )
            return None
        return self._arm.render(self.render_width, self.render_height)

    def close(self) -> None:
        """Release the offscreen renderer (GL context)."""
        self._arm.close()
