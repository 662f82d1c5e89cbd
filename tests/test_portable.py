"""pilco.portable: numpy's and OpenBLAS's AVX2 paths on every x86-64 CPU with AVX2, set
up when pilco is imported before numpy, and recorded in a run's provenance."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from pilco import portable
from pilco.experiment import provenance as prov

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FLAGS = portable.cpu_flags()
CAN_PIN = (sys.platform.startswith("linux") and portable.portable_environment(
    environ={}) == portable.PORTABLE_ENVIRONMENT)


def test_which_machines_get_the_portable_paths(tmp_path):
    avx2 = {"sse2", "avx", "avx2", "fma"}
    assert portable.portable_environment({}, avx2, "x86_64") == portable.PORTABLE_ENVIRONMENT
    # a CPU without AVX2 or FMA would crash in OpenBLAS's Haswell kernels: left alone
    assert portable.portable_environment({}, {"sse2", "avx", "fma"}, "x86_64") == {}
    assert portable.portable_environment({}, {"sse2", "avx", "avx2"}, "x86_64") == {}
    # not x86-64 (an ARM machine, or not Linux): left alone
    assert portable.portable_environment({}, avx2, "aarch64") == {}
    assert portable.portable_environment({}, avx2, "") == {}
    # the user's own setting wins, and the switch turns it all off
    mine = {"OPENBLAS_CORETYPE": "SkylakeX"}
    assert portable.portable_environment(mine, avx2, "x86_64") == {
        "NPY_DISABLE_CPU_FEATURES": portable.PORTABLE_ENVIRONMENT["NPY_DISABLE_CPU_FEATURES"]}
    assert portable.portable_environment({portable.SWITCH: "0"}, avx2, "x86_64") == {}
    # the flags as Linux lists them
    info = tmp_path / "cpuinfo"
    info.write_text("processor\t: 0\nflags\t\t: fpu sse2 avx2 fma\nbugs\t\t: none\n")
    assert portable.cpu_flags(str(info)) == {"fpu", "sse2", "avx2", "fma"}
    assert portable.cpu_flags(str(tmp_path / "none")) == set()


def _state(code: str, **env) -> dict:
    """``arithmetic_state()`` and the warning of a fresh process running ``code`` first."""
    environ = {k: v for k, v in os.environ.items()
               if k not in (*portable.PORTABLE_ENVIRONMENT, portable.SWITCH)}
    environ.update(env, PYTHONPATH=ROOT)
    script = (f"{code}\nimport json, scipy.linalg\n"
              "from pilco.portable import arithmetic_state, portability_warning\n"
              "print(json.dumps([arithmetic_state(), portability_warning()]))")
    out = subprocess.run([sys.executable, "-c", script], env=environ, capture_output=True,
                         text=True, timeout=120, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.skipif(not CAN_PIN, reason="needs Linux on an x86-64 CPU with AVX2 and FMA")
def test_importing_pilco_first_gives_the_portable_paths():
    state, warning = _state("import pilco, numpy")
    assert state["portable"] is True and warning is None
    assert state["numpy_avx512"] == [] and set(state["blas"]) == {"Haswell"}


@pytest.mark.skipif(not CAN_PIN or "avx512f" not in FLAGS,
                    reason="needs an x86-64 CPU with AVX-512, whose own paths differ")
def test_numpy_first_keeps_the_cpus_own_paths_and_says_so():
    state, warning = _state("import numpy, pilco")
    assert state["portable"] is False and "AVX512F" in state["numpy_avx512"]
    assert "numpy was loaded before pilco" in warning
    # asked for: no warning
    state, warning = _state("import pilco, numpy", PILCO_PORTABLE_ARITHMETIC="0")
    assert state["portable"] is False and warning is None


def test_a_run_records_its_arithmetic(monkeypatch):
    state = prov.provenance()["arithmetic"]
    assert set(state) == {"portable", "numpy_avx512", "blas", "numpy"}
    monkeypatch.setenv("OPENBLAS_CORETYPE", "Haswell")
    assert prov.provenance()["environment"]["OPENBLAS_CORETYPE"] == "Haswell"


def test_a_replay_that_parts_says_how_to_run_the_runs_own_arithmetic(tmp_path, monkeypatch):
    from types import SimpleNamespace

    from pilco.diagnose.replay import _arithmetic_hint
    from pilco.experiment.store import RunStore

    run = SimpleNamespace(store=RunStore(str(tmp_path)))
    summary = tmp_path / "summary.json"
    assert run.store.summary_path == str(summary)
    monkeypatch.setattr(portable, "arithmetic_state", lambda: {"portable": True})
    summary.write_text(json.dumps({"provenance": {"cpu": "x"}}))  # before it was recorded
    assert "PILCO_PORTABLE_ARITHMETIC=0" in _arithmetic_hint(run)
    summary.write_text(json.dumps({"provenance": {"arithmetic": {"portable": True}}}))
    assert _arithmetic_hint(run) == ""
    monkeypatch.setattr(portable, "arithmetic_state", lambda: {"portable": False})
    summary.write_text(json.dumps({"provenance": {"arithmetic": {"portable": False}}}))
    assert _arithmetic_hint(run) == ""  # this process runs the CPU's own arithmetic too
