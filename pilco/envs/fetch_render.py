"""The Fetch arm rendered at recorded joint angles in a fresh process, one without TensorFlow.

MuJoCo's EGL renderer and TensorFlow crash when used in one process (see
:meth:`pilco.envs.fetch_model.FetchArm.render`), and the joint-space reacher is purely
kinematic, so an episode is replayed exactly from its joint angles by
:func:`replay_fetch_frames` in a subprocess. Importing this module imports neither
TensorFlow nor MuJoCo; :mod:`pilco.plotting` gives the same function under its old name.
"""
from __future__ import annotations

import logging
import os
from typing import List, Sequence

import numpy as np

__all__ = ["replay_fetch_frames"]

# the renderer's warnings keep the logger they had in pilco.plotting
logger = logging.getLogger("pilco.plotting")


_REPLAY_CODE = """
import sys, numpy as np
from pilco.envs.fetch_render import _replay_fetch_worker
_replay_fetch_worker(sys.argv[1], sys.argv[2])
"""


def _replay_fetch_worker(in_path: str, out_path: str) -> None:
    """Subprocess side of :func:`replay_fetch_frames` (no TensorFlow in this process)."""
    from pilco.envs.fetch_reacher import FetchJointReacher

    with np.load(in_path) as f:
        qpos, target, size = f["qpos"], f["target"], f["size"]
    env = FetchJointReacher(render_mode="rgb_array", target=target,
                            render_width=int(size[0]), render_height=int(size[1]))
    frames = []
    for q in qpos:
        env.reset(options={"qpos": q})
        frames.append(env.render())
    np.savez_compressed(out_path, frames=np.stack(frames))
    # leave without tearing the GL context down (EGL teardown is noisy at exit)
    import os

    os._exit(0)


def replay_fetch_frames(qpos: np.ndarray, target: Sequence[float], width: int = 320,
                        height: int = 240, timeout: float = 300.0) -> List[np.ndarray]:
    """Render the Fetch arm at recorded joint angles, in a separate process.

    MuJoCo's EGL renderer and TensorFlow crash when loaded in the same process, and the
    joint-space reacher is purely kinematic, so an episode is replayed exactly from its
    joint angles by a fresh interpreter that never imports TensorFlow.

    Args:
        qpos: joint angles ``[T+1, 7]`` (state columns 3..9 of the reacher).
        target: the gripper target ``[3]`` (drawn as the red sphere).
        width, height: frame size in pixels.

    Returns:
        Frames ``uint8 [height, width, 3]``, one per row of ``qpos`` (empty on failure).
    """
    import subprocess
    import sys
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        src, dst = os.path.join(tmp, "in.npz"), os.path.join(tmp, "out.npz")
        np.savez(src, qpos=np.asarray(qpos, float), target=np.asarray(target, float),
                 size=np.array([width, height]))
        # the folder that holds the package, for the fresh interpreter's import
        root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
        env = dict(os.environ)
        env["PYTHONPATH"] = root + os.pathsep + env.get("PYTHONPATH", "")
        try:
            proc = subprocess.run([sys.executable, "-c", _REPLAY_CODE, src, dst], env=env,
                                  capture_output=True, text=True, timeout=timeout)
        except subprocess.TimeoutExpired:
            logger.warning("rendering the Fetch frames timed out")
            return []
        if proc.returncode != 0 or not os.path.exists(dst):
            logger.warning("rendering the Fetch frames failed: %s", proc.stderr[-500:])
            return []
        with np.load(dst) as f:
            return list(f["frames"])
