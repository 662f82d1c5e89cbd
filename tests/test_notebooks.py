"""The notebooks in ``notebooks/`` execute without error with tiny settings.

Every notebook runs with ``PILCO_NOTEBOOK_FAST=1`` in its own subprocess (nbclient, one
Jupyter kernel each); the three are started together by one module fixture so that their
TensorFlow start-up and tracing overlap, and each test then checks one notebook's result.
A notebook fails its test on any cell error or when it runs longer than ``TIMEOUT``.

Nothing is written into the repository: the kernels run in a temporary directory and the
executed notebooks are discarded (the test checks that ``notebooks/`` is unchanged).
The reacher notebooks need mujoco and gymnasium-robotics and are skipped without them.
"""
from __future__ import annotations

import importlib.util
import json
import os
import signal
import subprocess
import sys
import time

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
NOTEBOOK_DIR = os.path.join(ROOT, "notebooks")

#: notebook -> whether it needs the MuJoCo Fetch arm
NOTEBOOKS = {
    "01_moment_matching.ipynb": False,
    "02_reacher.ipynb": True,
    "03_damaged_reacher.ipynb": True,
}
#: seconds per notebook; they run in parallel, so this bounds the whole module too
#: (about 70 s on 2 busy cores; the slowest part is TensorFlow's start-up and tracing)
TIMEOUT = 150

# Executes one notebook; exit status 0 on success, 1 on a cell error (message on stdout).
_RUNNER = r"""
import sys, time
import nbformat
from nbclient import NotebookClient
from nbclient.exceptions import CellExecutionError, CellTimeoutError

path, workdir, timeout = sys.argv[1], sys.argv[2], int(sys.argv[3])
nb = nbformat.read(path, as_version=4)
client = NotebookClient(nb, timeout=timeout, kernel_name="python3", allow_errors=False,
                        resources={"metadata": {"path": workdir}})
t0 = time.perf_counter()
try:
    client.execute()
except (CellExecutionError, CellTimeoutError) as err:
    print(f"NOTEBOOK FAILED after {time.perf_counter() - t0:.1f} s:\n{err}")
    sys.exit(1)
print(f"NOTEBOOK OK in {time.perf_counter() - t0:.1f} s")
"""


def _missing_fetch() -> str:
    """Why the Fetch notebooks cannot run here ('' when they can)."""
    missing = [m for m in ("mujoco", "gymnasium_robotics") if importlib.util.find_spec(m) is None]
    if missing:
        return (f"needs {' and '.join(missing)} for the Fetch arm "
                "(pip install -e '.[robotics]')")
    return ""


def _missing_jupyter() -> str:
    missing = [m for m in ("nbformat", "nbclient", "ipykernel") if importlib.util.find_spec(m) is None]
    if missing:
        return f"needs {', '.join(missing)} to execute notebooks (pip install -e '.[tests]')"
    return ""


def _snapshot(directory):
    return {name: os.stat(os.path.join(directory, name)).st_mtime_ns
            for name in sorted(os.listdir(directory))}


@pytest.fixture(scope="module")
def executed(tmp_path_factory):
    """Run every runnable notebook at once; name -> (exit status, output) or skip reason."""
    reason = _missing_jupyter()
    if reason:
        pytest.skip(reason)
    env = dict(os.environ, PILCO_NOTEBOOK_FAST="1", TF_CPP_MIN_LOG_LEVEL="3",
               PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""),
               OMP_NUM_THREADS="1")  # three kernels share the machine: no BLAS thread pools
    env.pop("MPLBACKEND", None)  # the kernel chooses its inline backend
    fetch_reason = _missing_fetch()
    before = _snapshot(NOTEBOOK_DIR)
    procs, results = {}, {}
    for name, needs_fetch in NOTEBOOKS.items():
        if needs_fetch and fetch_reason:
            results[name] = fetch_reason
            continue
        workdir = tmp_path_factory.mktemp(name.split(".")[0])
        log = open(workdir / "output.txt", "w+", encoding="utf-8")
        cmd = [sys.executable, "-c", _RUNNER, os.path.join(NOTEBOOK_DIR, name), str(workdir),
               str(TIMEOUT)]
        # own session, ended as a whole on a timeout; the kernel (in a session of its own)
        # exits by itself once its parent is gone (ipykernel's parent poller)
        procs[name] = (subprocess.Popen(cmd, cwd=str(workdir), env=env, stdout=log,
                                        stderr=subprocess.STDOUT, text=True,
                                        start_new_session=True), log)
    deadline = time.perf_counter() + TIMEOUT + 15
    for name, (proc, log) in procs.items():
        try:
            proc.wait(timeout=max(deadline - time.perf_counter(), 1))
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
        log.seek(0)
        results[name] = (proc.returncode, log.read())
        log.close()
    results["_notebooks_dir_unchanged"] = before == _snapshot(NOTEBOOK_DIR)
    return results


@pytest.mark.parametrize("name", list(NOTEBOOKS))
def test_notebook_executes(executed, name):
    result = executed[name]
    if isinstance(result, str):
        pytest.skip(f"{name}: {result}")
    status, output = result
    print(f"{name}: {output.strip().splitlines()[-1:] or ['no output']}")  # pytest -rA shows it
    if status is None or status < 0:
        pytest.fail(f"{name} did not finish within {TIMEOUT} s:\n{output[-3000:]}")
    assert status == 0, f"{name} failed:\n{output[-5000:]}"
    assert "NOTEBOOK OK" in output


def test_notebooks_write_nothing_into_the_repository(executed):
    assert executed["_notebooks_dir_unchanged"], "executing the notebooks changed notebooks/"


@pytest.mark.parametrize("name", list(NOTEBOOKS))
def test_notebook_committed_without_outputs(name):
    """The committed notebooks carry no outputs or execution counts, and use a kernel
    named python3 with a FAST switch read from PILCO_NOTEBOOK_FAST."""
    with open(os.path.join(NOTEBOOK_DIR, name), encoding="utf-8") as f:
        nb = json.load(f)
    assert nb["metadata"]["kernelspec"]["name"] == "python3"
    code = [c for c in nb["cells"] if c["cell_type"] == "code"]
    assert code, f"{name} has no code cells"
    for cell in code:
        assert cell.get("outputs") == [], f"{name}: a code cell has outputs"
        assert cell.get("execution_count") is None, f"{name}: a code cell has an execution count"
    assert any("PILCO_NOTEBOOK_FAST" in "".join(c["source"]) for c in code)
