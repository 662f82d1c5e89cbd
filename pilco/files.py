"""Atomic file writes: a file is either its old complete version or its new one.

Every file pilco writes (agent and policy files, a run's data, progress and summary)
goes through :func:`atomic_write`: the content is written to a temporary file in the
destination's directory, flushed and ``fsync``'ed, then moved over the destination with
:func:`os.replace`, and the directory is ``fsync``'ed so that the rename itself survives
a power loss. A crash or a ``SIGKILL`` at any moment leaves no truncated file behind.

This module imports only the standard library and NumPy (the robot-side
:mod:`pilco.deploy` may use it).
"""
from __future__ import annotations

import contextlib
import json
import os
import tempfile
from typing import Any, Callable, Dict, IO

import numpy as np

__all__ = ["atomic_write", "write_npz_atomic", "write_json_atomic"]


def _fsync_directory(directory: str) -> None:
    """Make a rename in ``directory`` durable (POSIX; a no-op where impossible)."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def atomic_write(path, write: Callable[[IO[bytes]], None]) -> str:
    """Call ``write(binary_file)`` on a temporary file, then move it to ``path``.

    The directory is created if needed; an existing file's permission bits are kept
    (new files get ``0o644``). Returns the absolute path written.
    """
    path = os.path.abspath(os.fspath(path))
    directory = os.path.dirname(path)
    os.makedirs(directory, exist_ok=True)
    mode = (os.stat(path).st_mode & 0o777) if os.path.exists(path) else 0o644
    fd, tmp = tempfile.mkstemp(prefix="." + os.path.basename(path) + ".", suffix=".tmp",
                               dir=directory)
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, mode)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    _fsync_directory(directory)
    return path


def write_npz_atomic(path, arrays: Dict[str, np.ndarray]) -> str:
    """Save ``{name: array}`` to ``path`` as a compressed ``.npz``, atomically.

    ``path`` is used exactly as given (NumPy would append ``.npz`` to a file name).
    """
    return atomic_write(path, lambda fh: np.savez_compressed(fh, **arrays))


def _json_default(obj):
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return float(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def write_json_atomic(path, obj: Any) -> str:
    """Save ``obj`` as indented JSON at ``path``, atomically (NumPy scalars and arrays
    are written as numbers and lists)."""
    text = json.dumps(obj, indent=2, default=_json_default) + "\n"
    return atomic_write(path, lambda fh: fh.write(text.encode("utf-8")))
