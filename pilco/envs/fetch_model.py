"""The Fetch robot in MuJoCo: model loading, GL backend, forward kinematics, rendering.

The robot model is the ``FetchReach`` MJCF file shipped with gymnasium-robotics
(``assets/fetch/reach.xml``); only that file is used, the gymnasium-robotics Python package
is never imported. ``mujoco`` is imported lazily (when a :class:`FetchArm` is built), so
importing this module needs neither mujoco nor gymnasium-robotics.

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

import numpy as np

from pilco.envs import _checks as check

logger = logging.getLogger(__name__)

__all__ = [
    "ARM_JOINTS",
    "DEFAULT_CAMERA",
    "DEFAULT_FIXED_QPOS",
    "GRIP_SITE",
    "SHORT_NAMES",
    "TARGET_SITE",
    "FetchArm",
    "default_model_path",
    "resolve_joint",
    "resolve_joints",
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
        import mujoco  # deliberately lazy
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


def resolve_joints(joints: Any) -> tuple[int, ...]:
    """Sorted unique indices of a joint name or an iterable of names (see
    :func:`resolve_joint`)."""
    if isinstance(joints, str):
        joints = (joints,)
    if not isinstance(joints, Iterable):
        raise TypeError(f"joints must be a joint name or a sequence of names, got {joints!r}")
    return tuple(sorted({resolve_joint(j) for j in joints}))


def _model_file(model_path: Any) -> str:
    if model_path is None:
        return default_model_path()
    if not isinstance(model_path, (str, os.PathLike)):
        raise TypeError(f"model_path must be a path or None, got {type(model_path).__name__}")
    path = os.fspath(model_path)
    if not os.path.isfile(path):
        raise ValueError(f"model_path {path!r} is not an existing file")
    return path


class FetchArm:
    """The Fetch model posed kinematically: arm angles in, gripper position out.

    Holds the MuJoCo model and data, the arm joints' ``qpos`` addresses and limits, the
    fixed pose of the other joints, the red target sphere (``target0`` site) and an
    offscreen renderer made on first use.

    Args:
        model_path: MJCF file; ``None`` for gymnasium-robotics' ``fetch/reach.xml``.
        fixed_qpos: overrides of :data:`DEFAULT_FIXED_QPOS`, ``{joint name: value}``.
        target: position of the target sphere [m], shape ``(3,)``.
    """

    def __init__(self, model_path: Any, fixed_qpos: Mapping[str, float] | None,
                 target: np.ndarray) -> None:
        fixed = dict(DEFAULT_FIXED_QPOS)
        if fixed_qpos is not None:
            for name, value in check.mapping(fixed_qpos, "fixed_qpos").items():
                if not isinstance(name, str):
                    raise TypeError(f"fixed_qpos keys must be joint names, got {name!r}")
                if name in ARM_JOINTS:
                    raise ValueError(f"fixed_qpos cannot set the arm joint {name!r}")
                fixed[name] = check.real(
                    value, f"fixed_qpos[{name!r}]", allow_zero=True, allow_negative=True
                )
        self.mujoco = mujoco = _import_mujoco()
        self.model_path = _model_file(model_path)
        self.model = mujoco.MjModel.from_xml_path(self.model_path)
        self.data = mujoco.MjData(self.model)
        self.target = target

        arm_ids = [self._joint_id(n) for n in ARM_JOINTS]
        self.qpos_adr = np.array([self.model.jnt_qposadr[j] for j in arm_ids])
        limited = np.array([bool(self.model.jnt_limited[j]) for j in arm_ids])
        ranges = np.array([self.model.jnt_range[j] for j in arm_ids], dtype=np.float64)
        self.lower = np.where(limited, ranges[:, 0], -np.inf)
        self.upper = np.where(limited, ranges[:, 1], np.inf)

        self._base_qpos = self.model.qpos0.copy()
        for name, value in fixed.items():
            self._base_qpos[self.model.jnt_qposadr[self._joint_id(name)]] = value

        self._grip_site = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_SITE, GRIP_SITE)
        if self._grip_site < 0:
            raise ValueError(f"site {GRIP_SITE!r} not found in model {self.model_path}")
        self._target_site = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_SITE, TARGET_SITE)
        # The mocap body (FetchReach's end-effector controller, unused here) sits at the
        # world origin and draws green guide lines there: make its geoms invisible.
        mocap_body = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, "robot0:mocap")
        if mocap_body >= 0:
            self.model.geom_rgba[self.model.geom_bodyid == mocap_body, 3] = 0.0
        self._renderer = None
        self._camera = None

    def _joint_id(self, name: str) -> int:
        jid = self.mujoco.mj_name2id(self.model, self.mujoco.mjtObj.mjOBJ_JOINT, name)
        if jid < 0:
            raise ValueError(f"joint {name!r} not found in model {self.model_path}")
        return jid

    @property
    def qpos(self) -> np.ndarray:
        """Current arm joint angles [rad], shape ``(7,)`` (a copy)."""
        return self.data.qpos[self.qpos_adr].copy()

    @property
    def ee_position(self) -> np.ndarray:
        """Current gripper (``robot0:grip`` site) position [m], shape ``(3,)`` (a copy)."""
        return self.data.site_xpos[self._grip_site].copy()

    def update_marker(self) -> None:
        """Move the model's ``target0`` site (a red sphere) onto :attr:`target`."""
        if self._target_site < 0:
            return
        body = self.model.site_bodyid[self._target_site]
        # The site's parent body is static, so its world frame is known after mj_forward.
        rot = self.data.xmat[body].reshape(3, 3)
        self.model.site_pos[self._target_site] = rot.T @ (self.target - self.data.xpos[body])

    def set_qpos(self, q: np.ndarray) -> None:
        """Write the fixed pose and arm angles ``q`` (7,) and run forward kinematics."""
        self.data.qpos[:] = self._base_qpos
        self.data.qpos[self.qpos_adr] = q
        self.data.qvel[:] = 0.0
        self.mujoco.mj_forward(self.model, self.data)
        self.update_marker()

    def forward_kinematics(self, qpos: Any) -> np.ndarray:
        """Gripper position for arm angles ``qpos`` (7,), shape ``(3,)``; the current pose
        is restored afterwards. Joint limits are NOT applied."""
        q = check.vector(qpos, 7, "qpos")
        saved = self.qpos
        self.set_qpos(q)
        ee = self.ee_position
        self.set_qpos(saved)
        return ee

    def check_frame_size(self, width: int, height: int) -> None:
        """Refuse a frame larger than the model's offscreen buffer (ValueError)."""
        glob = self.model.vis.global_
        if width > glob.offwidth or height > glob.offheight:
            raise ValueError(
                f"render size {width}x{height} exceeds the model's offscreen buffer "
                f"{glob.offwidth}x{glob.offheight}"
            )

    def render(self, width: int, height: int) -> np.ndarray:
        """Offscreen frame ``uint8 (height, width, 3)`` from :data:`DEFAULT_CAMERA`.

        MuJoCo's EGL renderer and TensorFlow crash the process (a segmentation fault)
        when both are used in it, so rendering refuses with a ``RuntimeError`` once
        TensorFlow is imported: render in a process of its own, as
        :func:`pilco.envs.fetch_render.replay_fetch_frames` does from recorded joint
        angles.
        """
        if "tensorflow" in sys.modules and os.environ.get("PILCO_ALLOW_RENDER_WITH_TF") != "1":
            raise RuntimeError(
                "FetchJointReacher.render() in a process that imported TensorFlow would crash "
                "(MuJoCo EGL + TensorFlow); render in a separate process, e.g. with "
                "pilco.plotting.replay_fetch_frames (set PILCO_ALLOW_RENDER_WITH_TF=1 to try "
                "anyway)"
            )
        mujoco = self.mujoco
        if self._renderer is None:
            try:
                self._renderer = mujoco.Renderer(self.model, height, width)
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
        self.update_marker()
        mujoco.mj_forward(self.model, self.data)
        self._renderer.update_scene(self.data, camera=self._camera)
        return self._renderer.render().copy()

    def close(self) -> None:
        """Release the offscreen renderer (GL context)."""
        if self._renderer is not None:
            try:
                self._renderer.close()
            except Exception:  # best effort at teardown
                logger.debug("Ignoring error while closing the MuJoCo renderer", exc_info=True)
            self._renderer = None
