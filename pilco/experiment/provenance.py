"""Where a run's numbers came from: code version, library versions, CPU and the settings
of TensorFlow's arithmetic.

A seed's outcome depends on more than the seed: the same seed gives another result where
numpy or BLAS take their CPU's own paths (:mod:`pilco.portable`), with another thread
count, and after small code changes. :func:`provenance` collects those
facts once per process for ``summary.json`` (key ``provenance``), so two runs of a sweep
can be compared knowing whether they ran the same code the same way.
"""
from __future__ import annotations

import functools
import os
import platform
import subprocess
from importlib import metadata
from typing import Any, Dict, Optional

from ..portable import arithmetic_state

__all__ = ["provenance", "git_commit", "cpu_model"]

#: packages whose versions change the arithmetic or the environments
PACKAGES = ("pilco", "tensorflow", "tensorflow-probability", "gpflow", "numpy", "scipy",
            "mujoco", "gymnasium")

#: environment variables that change TensorFlow's arithmetic or its thread pools
ENVIRONMENT = ("TF_ENABLE_ONEDNN_OPTS", "TF_NUM_INTRAOP_THREADS", "TF_NUM_INTEROP_THREADS",
               "OMP_NUM_THREADS", "PILCO_ARITHMETIC_OPTIMIZER", "PILCO_PORTABLE_ARITHMETIC",
               "PILCO_PAIR_GROUPS", "NPY_DISABLE_CPU_FEATURES", "OPENBLAS_CORETYPE")


def git_commit(directory: Optional[str] = None) -> Optional[Dict[str, Any]]:
    """``{"commit": sha, "dirty": bool}`` of the git checkout holding ``directory``
    (default: this package), ``dirty`` when tracked files differ from the commit; None
    outside a checkout or without git."""
    directory = directory or os.path.dirname(os.path.abspath(__file__))

    def git(*args: str) -> Optional[str]:
        try:
            out = subprocess.run(("git", *args), cwd=directory, capture_output=True,
                                 text=True, timeout=10, check=False)
        except (OSError, subprocess.SubprocessError):
            return None
        return out.stdout.strip() if out.returncode == 0 else None

    sha = git("rev-parse", "HEAD")
    if not sha:
        return None
    status = git("status", "--porcelain", "--untracked-files=no")
    return {"commit": sha, "dirty": bool(status)}


def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo`` on Linux), else ``platform.processor()``."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _version(package: str) -> Optional[str]:
    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return None


@functools.lru_cache(maxsize=1)
def _static() -> Dict[str, Any]:
    return {
        "git": git_commit(),
        "versions": {p: _version(p) for p in PACKAGES},
        "python": platform.python_version(),
        "cpu": cpu_model(),
        "cpu_count": os.cpu_count(),
        "arithmetic": arithmetic_state(),
        "host": platform.node(),
    }


def provenance() -> Dict[str, Any]:
    """Code version (``git``: commit and whether tracked files were changed; None
    outside a checkout), package ``versions``, ``python``, ``cpu`` model and
    ``cpu_count``, the paths of numpy's and BLAS's ``arithmetic``
    (:func:`pilco.portable.arithmetic_state`), ``host``, and the ``environment``
    variables of :data:`ENVIRONMENT` that are set (all but the environment are read once
    per process)."""
    env = {k: os.environ[k] for k in ENVIRONMENT if k in os.environ}
    return {**_static(), "environment": env}
