"""Joint-space reacher on the 7-DoF Fetch arm (the PILCO paper's robot task).

Unlike gymnasium-robotics' ``FetchReach`` (4-D end-effector action, physics steps), this
environment drives the seven arm joints directly: an action is a relative rotation of
each joint, the new joint angles are written into ``qpos`` and MuJoCo forward kinematics
(``mujoco.mj_forward``, no physics step) gives the gripper position. The robot model is
the ``FetchReach`` MJCF file shipped with gymnasium-robotics (``assets/fetch/reach.xml``).

``mujoco`` is imported lazily (on construction), so importing this module does not need
mujoco or gymnasium-robotics; only the XML file of gymnasium-robotics is used, its Python
package is never imported.

Joint limits of the model (rad): shoulder_pan [-1.6056, 1.6056], shoulder_lift
[-1.221, 1.518], elbow_flex [-2.251, 2.251], wrist_flex [-2.16, 2.16];
upperarm_roll, forearm_roll and wrist_roll are unlimited (continuous).
"""
from __future__ import annotations

import importlib.util
import logging
import os
import sys
from collections.abc import Iterable, Mapping
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

logger = logging.getLogger(__name__)

__all__ = [
    "ARM_JOINTS",
    "DEFAULT_START_QPOS",
    "DEFAULT_TARGET",
    "DEFAULT_FIXED_QPOS",
    "FetchJointReacher",
    "default_model_path",
]

#: Full MuJoCo names of the seven arm joints, in action/observation order.
ARM_JOINTS: tuple[str, ...] = (
    "robot0:shoulder_pan_joint",
    "robot0:shoulder_lift_joint",
    "robot0:upperarm_roll_joint",
    "robot0:elbow_flex_joint",
    "robot0:forearm_roll_joint",
    "robot0:wrist_flex_joint",
    "robot0:wrist_roll_joint",
)

#: Short names (``"elbow_flex"``) of :data:`ARM_JOINTS`.
SHORT_NAMES: tuple[str, ...] = tuple(
    n.removeprefix("robot0:").removesuffix("_joint") for n in ARM_JOINTS
)

#: Default start joint angles [rad], shape ``(7,)``.
DEFAULT_START_QPOS: tuple[float, ...] = (0.0, -1.0, 0.0, 2.0, 0.0, 0.5, 0.0)

#: Default target of the gripper [m], shape ``(3,)``.
DEFAULT_TARGET: tuple[float, float, float] = (1.2, 0.38, 0.38)

#: Values of the non-arm joints, held fixed. The base slides are those of gymnasium's
#: FetchReach (``initial_qpos``); torso, head and fingers stay at the model's defaults
#: (the head tilt's reference angle is 0.06 rad). FetchReach itself lets the torso lift
#: settle to ~1.3 mm during its physics warm-up, which raises the gripper by that amount.
DEFAULT_FIXED_QPOS: dict[str, float] = {
    "robot0:slide0": 0.4049,
    "robot0:slide1": 0.48,
    "robot0:slide2": 0.0,
    "robot0:torso_lift_joint": 0.0,
    "robot0:head_pan_joint": 0.0,
    "robot0:head_tilt_joint": 0.06,
    "robot0:r_gripper_finger_joint": 0.0,
    "robot0:l_gripper_finger_joint": 0.0,
}

DAMAGE_MODES = ("zero", "stuck")
GRIP_SITE = "robot0:grip"
TARGET_SITE = "target0"

#: Free camera like gymnasium-robotics' Fetch default view.
DEFAULT_CAMERA = {
    "distance": 2.5,
    "azimuth": 132.0,
    "elevation": -14.0,
    "lookat": (1.3, 0.75, 0.55),
}


def _default_gl_backend() -> None:
    """Select MuJoCo's headless EGL backend unless ``MUJOCO_GL`` is already set.

    mujoco reads ``MUJOCO_GL`` when it is first imported, so this runs when this module
    is imported (before any later ``import mujoco``) and again before the lazy import.
    EGL exists on Linux only; elsewhere mujoco's own default is kept.
    """
    if sys.platform.startswith("linux"):
        os.environ.setdefault("MUJOCO_GL", "egl")


_default_gl_backend()


def _import_mujoco():
    """Import mujoco lazily (after choosing the GL backend)."""
    _default_gl_backend()
    try:
        import mujoco  # noqa: PLC0415 - deliberately lazy
    except ImportError as exc:  # pragma: no cover - depends on the installation
        raise ImportError(
            "FetchJointReacher needs mujoco and gymnasium-robotics: "
            "pip install 'pilco[robotics]'"
        ) from exc
    except Exception as exc:  # pragma: no cover - e.g. MUJOCO_GL names a missing backend
        raise ImportError(
            f"mujoco failed to import with MUJOCO_GL={os.environ.get('MUJOCO_GL')!r} "
            f"(unset it or choose an installed backend: egl, osmesa, glfw): {exc!r}"
        ) from exc
    return mujoco


def default_model_path() -> str:
    """Path of gymnasium-robotics' ``fetch/reach.xml`` (without importing the package).

    Raises:
        ImportError: gymnasium-robotics is not installed.
        FileNotFoundError: the package has no such asset.
    """
    spec = importlib.util.find_spec("gymnasium_robotics")
    if spec is None or not spec.submodule_search_locations:
        raise ImportError(
            "FetchJointReacher needs the Fetch model of gymnasium-robotics: "
            "pip install 'pilco[robotics]'"
        )
    root = list(spec.submodule_search_locations)[0]
    path = os.path.join(root, "envs", "assets", "fetch", "reach.xml")
    if not os.path.isfile(path):
        raise FileNotFoundError(f"Fetch model not found at {path}")
    return path


def _vector(value: Any, size: int, name: str) -> np.ndarray:
    """Convert to a finite float64 array of shape ``(size,)``."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be array-like of {size} numbers: {exc}") from exc
    if arr.shape != (size,):
        raise ValueError(f"{name} must have shape ({size},), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {arr}")
    return arr.copy()


def _nonneg_float(value: Any, name: str, *, strict: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
    value = float(value)
    if not np.isfinite(value) or value < 0 or (strict and value == 0):
        raise ValueError(f"{name} must be finite and {'> 0' if strict else '>= 0'}, got {value}")
    return value


def resolve_joint(name: Any) -> int:
    """Index (0..6) of an arm joint given a short (``"elbow_flex"``), ``"elbow_flex_joint"``
    or full (``"robot0:elbow_flex_joint"``) name.

    Raises:
        TypeError: ``name`` is not a string.
        ValueError: unknown joint (the message lists the valid names).
    """
    if not isinstance(name, str):
        raise TypeError(f"joint names must be strings, got {type(name).__name__}")
    short = name.removeprefix("robot0:").removesuffix("_joint")
    if short in SHORT_NAMES:
        return SHORT_NAMES.index(short)
    raise ValueError(
        f"Unknown Fetch arm joint {name!r}; valid short names: {list(SHORT_NAMES)} "
        f"(or full names: {list(ARM_JOINTS)})"
    )


def _resolve_joints(joints: Any) -> tuple[int, ...]:
    if isinstance(joints, str):
        joints = (joints,)
    if not isinstance(joints, Iterable):
        raise TypeError(f"joints must be a joint name or a sequence of names, got {joints!r}")
    return tuple(sorted({resolve_joint(j) for j in joints}))


def _check_mode(mode: Any) -> str:
    if mode not in DAMAGE_MODES:
        raise ValueError(f"damage_mode must be one of {list(DAMAGE_MODES)}, got {mode!r}")
    return mode


class FetchJointReacher(gymnasium.Env):
    """Reach a 3-D target with the Fetch arm's gripper by rotating its seven joints.

    Observation, shape ``(10,)`` float64: gripper (``robot0:grip`` site) position xyz [m]
    followed by the 7 arm joint angles [rad] in :data:`ARM_JOINTS` order.

    Action, shape ``(7,)``: relative rotation of each joint [rad], clipped to
    ``[-max_action, max_action]`` (default 0.1); the new angles are clipped to the
    model's joint limits (``jnt_range``; the three roll joints are unlimited).

    Reward: ``-||ee - target||``. ``terminated`` when the distance is below
    ``distance_threshold``; ``truncated`` after ``max_episode_steps`` steps (``None``
    disables the internal limit). ``info = {"distance", "is_success", "ee_position",
    "qpos"}``.

    Damage (the agent is not told; the observation keeps its form): ``damaged_joints``
    (short or full names) with ``damage_mode``:

    - ``"zero"`` (the paper's variant): the joints are forced to 0 rad at reset and at
      every step whatever the command;
    - ``"stuck"``: the joints keep the angle they had when the damage happened (the start
      pose of each episode, or the current angle when :meth:`damage` is called mid-run).

    The damage persists across resets until :meth:`repair` is called.

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
        damage_mode: ``"zero"`` or ``"stuck"``.
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
        damage_mode: str = "zero",
        fixed_qpos: Mapping[str, float] | None = None,
        model_path: str | None = None,
        render_width: int = 640,
        render_height: int = 480,
    ) -> None:
        super().__init__()
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode must be None or one of {self.metadata['render_modes']}, "
                f"got {render_mode!r}"
            )
        self.render_mode = render_mode

        self._start_qpos = _vector(start_qpos, 7, "start_qpos")
        self._target = _vector(target, 3, "target")
        self.start_noise = _nonneg_float(start_noise, "start_noise")
        self.max_action = _nonneg_float(max_action, "max_action", strict=True)
        self.distance_threshold = _nonneg_float(distance_threshold, "distance_threshold")
        if max_episode_steps is not None:
            if isinstance(max_episode_steps, bool) or not isinstance(
                max_episode_steps, (int, np.integer)
            ):
                raise TypeError(
                    "max_episode_steps must be an int or None, "
                    f"got {type(max_episode_steps).__name__}"
                )
            if max_episode_steps <= 0:
                raise ValueError(f"max_episode_steps must be > 0, got {max_episode_steps}")
            max_episode_steps = int(max_episode_steps)
        self.max_episode_steps = max_episode_steps
        self._damaged = _resolve_joints(damaged_joints)
        self._damage_mode = _check_mode(damage_mode)
        self._stuck_values = np.zeros(len(self._damaged))

        for name, value in (("render_width", render_width), ("render_height", render_height)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise TypeError(f"{name} must be an int, got {type(value).__name__}")
            if value < 16:
                raise ValueError(f"{name} must be >= 16 pixels, got {value}")
        self.render_width, self.render_height = int(render_width), int(render_height)

        # ---- MuJoCo model (lazy import) ----
        self._mujoco = mujoco = _import_mujoco()
        self.model_path = default_model_path() if model_path is None else str(model_path)
        self.model = mujoco.MjModel.from_xml_path(self.model_path)
        self.data = mujoco.MjData(self.model)
        if (
            self.render_width > self.model.vis.global_.offwidth
            or self.render_height > self.model.vis.global_.offheight
        ):
            raise ValueError(
                f"render size {self.render_width}x{self.render_height} exceeds the model's "
                f"offscreen buffer {self.model.vis.global_.offwidth}x"
                f"{self.model.vis.global_.offheight}"
            )

        def joint_id(name: str) -> int:
            jid = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_JOINT, name)
            if jid < 0:
                raise ValueError(f"joint {name!r} not found in model {self.model_path}")
            return jid

        arm_ids = [joint_id(n) for n in ARM_JOINTS]
        self._arm_qpos_adr = np.array([self.model.jnt_qposadr[j] for j in arm_ids])
        limited = np.array([bool(self.model.jnt_limited[j]) for j in arm_ids])
        ranges = np.array([self.model.jnt_range[j] for j in arm_ids], dtype=np.float64)
        self._lower = np.where(limited, ranges[:, 0], -np.inf)
        self._upper = np.where(limited, ranges[:, 1], np.inf)

        fixed = dict(DEFAULT_FIXED_QPOS)
        if fixed_qpos is not None:
            if not isinstance(fixed_qpos, Mapping):
                raise TypeError(f"fixed_qpos must be a mapping, got {type(fixed_qpos).__name__}")
            for name, value in fixed_qpos.items():
                if name in ARM_JOINTS:
                    raise ValueError(f"fixed_qpos cannot set the arm joint {name!r}")
                fixed[name] = float(value)
        self._base_qpos = self.model.qpos0.copy()
        for name, value in fixed.items():
            self._base_qpos[self.model.jnt_qposadr[joint_id(name)]] = value

        self._grip_site = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_SITE, GRIP_SITE)
        if self._grip_site < 0:
            raise ValueError(f"site {GRIP_SITE!r} not found in model {self.model_path}")
        self._target_site = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_SITE, TARGET_SITE)
        # The mocap body (FetchReach's end-effector controller, unused here) sits at the
        # world origin and draws green guide lines there: make its geoms invisible.
        mocap_body = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, "robot0:mocap")
        if mocap_body >= 0:
            self.model.geom_rgba[self.model.geom_bodyid == mocap_body, 3] = 0.0

        self.action_space = spaces.Box(
            low=-self.max_action, high=self.max_action, shape=(7,), dtype=np.float64
        )
        self.observation_space = spaces.Box(
            low=-np.inf, high=np.inf, shape=(10,), dtype=np.float64
        )

        self._renderer = None
        self._camera = None
        self._elapsed_steps = 0
        self._ready = False
        # Put the arm in its start pose so ee_position etc. are meaningful before reset().
        self._set_qpos(self._start_qpos.copy())

    # --------------------------------------------------------------- properties
    @property
    def joint_names(self) -> tuple[str, ...]:
        """Full names of the arm joints, action/observation order."""
        return ARM_JOINTS

    @property
    def joint_limits(self) -> np.ndarray:
        """Joint limits ``[[low, high], ...]`` [rad], shape ``(7, 2)``; ±inf if unlimited."""
        return np.stack([self._lower, self._upper], axis=1)

    @property
    def qpos(self) -> np.ndarray:
        """Current arm joint angles [rad], shape ``(7,)`` (a copy)."""
        return self.data.qpos[self._arm_qpos_adr].copy()

    @property
    def ee_position(self) -> np.ndarray:
        """Current gripper (``robot0:grip`` site) position [m], shape ``(3,)`` (a copy)."""
        return self.data.site_xpos[self._grip_site].copy()

    @property
    def target(self) -> np.ndarray:
        """Target position [m], shape ``(3,)`` (a copy)."""
        return self._target.copy()

    @target.setter
    def target(self, value: Any) -> None:
        self._target = _vector(value, 3, "target")
        self._update_marker()

    @property
    def start_qpos(self) -> np.ndarray:
        """Start joint angles [rad], shape ``(7,)`` (a copy)."""
        return self._start_qpos.copy()

    @start_qpos.setter
    def start_qpos(self, value: Any) -> None:
        self._start_qpos = _vector(value, 7, "start_qpos")

    @property
    def damaged_joints(self) -> tuple[str, ...]:
        """Short names of the damaged joints."""
        return tuple(SHORT_NAMES[i] for i in self._damaged)

    @property
    def damage_mode(self) -> str:
        """``"zero"`` or ``"stuck"``."""
        return self._damage_mode

    # ------------------------------------------------------------- kinematics
    def _update_marker(self) -> None:
        """Move the model's ``target0`` site (a red sphere) onto the target."""
        if self._target_site < 0:
            return
        body = self.model.site_bodyid[self._target_site]
        # The site's parent body is static, so its world frame is known after mj_forward.
        rot = self.data.xmat[body].reshape(3, 3)
        self.model.site_pos[self._target_site] = rot.T @ (self._target - self.data.xpos[body])

    def _set_qpos(self, q: np.ndarray) -> None:
        """Write the non-arm pose and arm angles ``q`` (7,) and run forward kinematics."""
        self.data.qpos[:] = self._base_qpos
        self.data.qpos[self._arm_qpos_adr] = q
        self.data.qvel[:] = 0.0
        self._mujoco.mj_forward(self.model, self.data)
        self._update_marker()

    def forward_kinematics(self, qpos: Any) -> np.ndarray:
        """Gripper position for arm angles ``qpos`` (7,), shape ``(3,)``; the env's
        current pose is restored afterwards. Joint limits and damage are NOT applied."""
        q = _vector(qpos, 7, "qpos")
        saved = self.qpos
        self._set_qpos(q)
        ee = self.ee_position
        self._set_qpos(saved)
        return ee

    def _apply_damage(self, q: np.ndarray) -> np.ndarray:
        if self._damaged:
            idx = list(self._damaged)
            q[idx] = 0.0 if self._damage_mode == "zero" else self._stuck_values
        return q

    def distance(self) -> float:
        """Distance [m] of the gripper to the target."""
        return float(np.linalg.norm(self.ee_position - self._target))

    # ----------------------------------------------------------------- damage
    def damage(self, joints: Any = ("elbow_flex",), mode: str = "zero") -> None:
        """Damage joints of a running env (replaces any previous damage).

        ``"zero"``: from the next step on the joints are forced to 0 rad.
        ``"stuck"``: the joints stay at their current angles.

        Args:
            joints: joint name or names (short or full).
            mode: ``"zero"`` or ``"stuck"``.
        """
        damaged = _resolve_joints(joints)
        self._damage_mode = _check_mode(mode)
        self._damaged = damaged
        self._stuck_values = self.qpos[list(damaged)] if damaged else np.zeros(0)
        logger.info("Damaged Fetch joints %s (mode %s)", self.damaged_joints, mode)

    def repair(self) -> None:
        """Remove all damage (the joints respond to commands again from the next step)."""
        self._damaged = ()
        self._stuck_values = np.zeros(0)
        logger.info("Repaired all Fetch joints")

    # ---------------------------------------------------------------- gym API
    def _obs(self) -> np.ndarray:
        return np.concatenate([self.ee_position, self.qpos])

    def _info(self) -> dict[str, Any]:
        d = self.distance()
        return {
            "distance": d,
            "is_success": bool(d < self.distance_threshold),
            "ee_position": self.ee_position,
            "qpos": self.qpos,
        }

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Put the arm in the start pose (plus ``start_noise``).

        Args:
            seed: seeds ``self.np_random``.
            options: optional ``{"qpos": (7,) start angles for this episode,
                "target": (3,) new target (kept for later episodes)}``.

        Returns:
            ``(observation (10,), info)``.
        """
        super().reset(seed=seed)
        if options is not None and not isinstance(options, dict):
            raise TypeError(f"options must be a dict or None, got {type(options).__name__}")
        options = options or {}
        unknown = set(options) - {"qpos", "target"}
        if unknown:
            raise ValueError(f"Unknown reset options {sorted(unknown)}; valid: ['qpos', 'target']")
        if "target" in options:
            self._target = _vector(options["target"], 3, "options['target']")
        q = _vector(options["qpos"], 7, "options['qpos']") if "qpos" in options else self.start_qpos
        if self.start_noise > 0:
            q = q + self.start_noise * self.np_random.standard_normal(7)
        q = np.clip(q, self._lower, self._upper)
        if self._damaged and self._damage_mode == "stuck":
            self._stuck_values = q[list(self._damaged)].copy()
        q = self._apply_damage(q)
        self._set_qpos(q)
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
        try:
            a = np.asarray(action, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise TypeError(f"action must be array-like of 7 numbers: {exc}") from exc
        if a.shape != (7,):
            raise ValueError(f"action must have shape (7,), got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"action must be finite, got {a}")
        a = np.clip(a, -self.max_action, self.max_action)
        q = np.clip(self.qpos + a, self._lower, self._upper)
        q = self._apply_damage(q)
        self._set_qpos(q)
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

        MuJoCo's EGL renderer and TensorFlow crash the process (a segmentation fault)
        when both are used in it, so rendering refuses with a ``RuntimeError`` once
        TensorFlow is imported: render in a process of its own, as
        :func:`pilco.plotting.replay_fetch_frames` does from recorded joint angles.
        """
        if self.render_mode is not None and "tensorflow" in sys.modules and \
                os.environ.get("PILCO_ALLOW_RENDER_WITH_TF") != "1":
            raise RuntimeError(
                "FetchJointReacher.render() in a process that imported TensorFlow would crash "
                "(MuJoCo EGL + TensorFlow); render in a separate process, e.g. with "
                "pilco.plotting.replay_fetch_frames (set PILCO_ALLOW_RENDER_WITH_TF=1 to try "
                "anyway)"
            )
        if self.render_mode is None:
            logger.warning(
                "FetchJointReacher.render() called without a render_mode; "
                "construct with render_mode='rgb_array'"
            )
            return None
        mujoco = self._mujoco
        if self._renderer is None:
            try:
                self._renderer = mujoco.Renderer(
                    self.model, self.render_height, self.render_width
                )
            except Exception as exc:
                raise RuntimeError(
                    "Cannot create a MuJoCo offscreen renderer (MUJOCO_GL="
                    f"{os.environ.get('MUJOCO_GL')!r}; mujoco reads it at its first import, "
                    "so set it before importing mujoco, e.g. MUJOCO_GL=egl or osmesa "
                    f"when headless): {exc}"
                ) from exc
            cam = mujoco.MjvCamera()
            cam.type = mujoco.mjtCamera.mjCAMERA_FREE
            cam.distance = DEFAULT_CAMERA["distance"]
            cam.azimuth = DEFAULT_CAMERA["azimuth"]
            cam.elevation = DEFAULT_CAMERA["elevation"]
            cam.lookat[:] = DEFAULT_CAMERA["lookat"]
            self._camera = cam
        self._update_marker()
        mujoco.mj_forward(self.model, self.data)
        self._renderer.update_scene(self.data, camera=self._camera)
        return self._renderer.render().copy()

    def close(self) -> None:
        """Release the offscreen renderer (GL context)."""
        if self._renderer is not None:
            try:
                self._renderer.close()
            except Exception:  # noqa: BLE001 - best effort at teardown
                logger.debug("Ignoring error while closing the MuJoCo renderer", exc_info=True)
            self._renderer = None
