"""Test-suite set-up shared by ``tests/`` and the notebooks in ``notebooks/``.

``pytest.ini`` runs ``tests/`` and ``notebooks/`` with ``--nbmake``: every notebook is one
test, executed top to bottom in a fresh Jupyter kernel (cwd ``notebooks/``) and failed on
any cell error. The notebooks are stored with the outputs of their full settings
(``python notebooks/execute.py`` writes them; ``tests/test_notebooks.py`` checks them);
this run ignores those outputs and discards its own. This file

* makes the kernels use the notebooks' small settings: ``PILCO_NOTEBOOK_FAST=1`` unless
  the variable is already set (``PILCO_NOTEBOOK_FAST=0 python -m pytest notebooks``
  executes them with their full settings), and MuJoCo's headless EGL backend on Linux
  unless ``MUJOCO_GL`` is set. Kernels inherit this process's environment, so it is set
  here, at import, before any kernel starts;
* turns TensorFlow's arithmetic optimizer off, as every run does
  (:func:`pilco.runtime.reproducible_arithmetic`);
* compiles XLA programs (``tests/test_xla.py``) without LLVM's optimisations
  (``XLA_FLAGS=--xla_backend_optimization_level=0`` unless ``XLA_FLAGS`` is set): the
  tests check values, not speed, and compile in half the time;
* limits each notebook to ``NOTEBOOK_TIMEOUT`` seconds in all (pytest-timeout; a
  ``--timeout`` on the command line replaces it) on top of nbmake's per-cell
  ``--nbmake-timeout``;
* skips a notebook whose metadata lists Python modules that are not installed
  (``"pilco": {"requires": [...]}``; the reacher notebooks need mujoco and
  gymnasium_robotics);
* fails a notebook whose execution changed anything in ``notebooks/``, and refuses
  nbmake's ``--overwrite`` (it would store the FAST outputs, uncleaned, in place of the
  full ones: ``python notebooks/execute.py`` stores outputs).
"""
from __future__ import annotations

import importlib.util
import json
import os
import sys
from pathlib import Path

import pytest

os.environ.setdefault("PILCO_NOTEBOOK_FAST", "1")
os.environ.setdefault("XLA_FLAGS", "--xla_backend_optimization_level=0")
if sys.platform.startswith("linux"):
    os.environ.setdefault("MUJOCO_GL", "egl")   # as pilco.envs does; EGL is Linux-only

ROOT = Path(__file__).resolve().parent
NOTEBOOK_DIR = ROOT / "notebooks"

#: seconds per notebook, all cells together (the issue's limit for the full settings;
#: FAST runs take 15-35 s each and full ones 25-110 s on 2 shared cores)
NOTEBOOK_TIMEOUT = 180


def _is_notebook(item) -> bool:
    return bool(getattr(item, "nbmake", False))


def notebook_requirements(path) -> list:
    """Python modules a notebook declares in its metadata (``pilco.requires``)."""
    with open(path, encoding="utf-8") as f:
        meta = json.load(f).get("metadata", {})
    return list(meta.get("pilco", {}).get("requires", []))


def _missing(modules) -> list:
    missing = []
    for name in modules:
        try:
            if importlib.util.find_spec(name) is None:
                missing.append(name)
        except (ImportError, ValueError):
            missing.append(name)
    return missing


def pytest_configure(config):
    if config.getoption("overwrite", False):
        raise pytest.UsageError(
            "nbmake --overwrite would store the notebooks' FAST outputs; "
            "`python notebooks/execute.py` executes them with the full settings and stores "
            "cleaned outputs")


def pytest_collection_modifyitems(config, items):
    explicit_timeout = config.getoption("timeout", None) is not None
    for item in items:
        if not _is_notebook(item):
            continue
        if not explicit_timeout:
            item.add_marker(pytest.mark.timeout(NOTEBOOK_TIMEOUT))
        missing = _missing(notebook_requirements(item.path))
        if missing:
            item.add_marker(pytest.mark.skip(
                reason=f"{item.path.name} needs {' and '.join(missing)} "
                       "(pip install -e '.[tests]')"))


def _snapshot(directory: Path) -> dict:
    """Every file under `directory` -> (size, mtime); Jupyter's checkpoints left out."""
    out = {}
    for path in sorted(directory.rglob("*")):
        if ".ipynb_checkpoints" in path.parts or not path.is_file():
            continue
        st = path.stat()
        out[str(path.relative_to(directory))] = (st.st_size, st.st_mtime_ns)
    return out


@pytest.hookimpl(wrapper=True)
def pytest_runtest_call(item):
    if not _is_notebook(item):
        return (yield)
    directory = Path(item.path).parent
    before = _snapshot(directory)
    result = yield
    after = _snapshot(directory)
    changed = sorted(name for name in before.keys() | after.keys()
                     if before.get(name) != after.get(name))
    if changed:
        raise NotebookWroteFiles(f"executing it changed {', '.join(changed)} in {directory}")
    return result


class NotebookWroteFiles(Exception):
    pass


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item, call):
    """A plain message instead of nbmake's 'NBMAKE INTERNAL ERROR' and a pytest traceback
    when a notebook timed out as a whole or wrote into notebooks/."""
    report = yield
    if _is_notebook(item) and report.failed and call.excinfo is not None:
        exc = call.excinfo.value
        if isinstance(exc, NotebookWroteFiles) or (
                isinstance(exc, pytest.fail.Exception) and "pytest-timeout" in str(exc)):
            report.longrepr = f"{item.path.name}: {exc}"
    return report


@pytest.fixture(scope="session", autouse=True)
def _reproducible_arithmetic():
    """Tests compute as runs do: every run's process turns Grappler's arithmetic optimizer
    off (``pilco.runtime.configure_threads``, which ``Task.parse`` calls in a test's
    process too). Set once per worker before its first test, a test's result does not
    depend on which tests its worker ran before it."""
    from pilco.runtime import reproducible_arithmetic

    reproducible_arithmetic()
