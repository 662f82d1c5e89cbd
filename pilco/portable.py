"""The same floating-point results on every x86-64 CPU with AVX2.

numpy chooses some of its loops (``sin``, ``cos``, ``exp``, ...) by the CPU's instruction
set when it is imported, and OpenBLAS (numpy's and scipy's) its kernels when it is loaded.
On a CPU with AVX-512 both take paths whose results differ in the last bits from those of
a CPU with AVX2 only, and a PILCO run turns last bits into another path: the same seed
and code learn differently on the two CPUs from the first learned episode on (measured in
docs/success-rates.md, "The CPU, found and held still"). TensorFlow's float64 work runs
the same code on every x86-64 CPU (its kernels are compiled for AVX2, and oneDNN takes no
float64), so with numpy and OpenBLAS held to their AVX2 paths a seed gives the same run
on x86-64 CPUs with AVX2, with AVX-512 or without.

:func:`use_portable_arithmetic` holds them there by the two variables they read when
they are loaded: ``NPY_DISABLE_CPU_FEATURES`` (numpy's AVX-512 loops off) and
``OPENBLAS_CORETYPE=Haswell`` (OpenBLAS's AVX2 kernels). :mod:`pilco` calls it when it is
imported, before it imports numpy; processes started from it (a sweep's runs) inherit the
variables. It leaves alone a variable the user set, a CPU without AVX2 and FMA, anything
but Linux on x86-64, and everything when ``PILCO_PORTABLE_ARITHMETIC=0``. A process
that imported numpy before :mod:`pilco` keeps its CPU's own paths:
:func:`arithmetic_state` says which paths a process runs (a run records it in its
provenance) and :func:`portability_warning` words what that means.

This module imports nothing but the standard library.
"""
from __future__ import annotations

import os
import platform
import sys
from typing import Any, Dict, Optional, Set

__all__ = ["SWITCH", "PORTABLE_ENVIRONMENT", "cpu_flags", "portable_environment",
           "use_portable_arithmetic", "arithmetic_state", "portability_warning"]

#: ``PILCO_PORTABLE_ARITHMETIC=0`` keeps the CPU's own numpy and OpenBLAS paths
SWITCH = "PILCO_PORTABLE_ARITHMETIC"

#: the variables and values that hold numpy and OpenBLAS to their AVX2 paths (numpy
#: ignores the names of features a CPU does not have)
PORTABLE_ENVIRONMENT = {
    "NPY_DISABLE_CPU_FEATURES": "AVX512F AVX512CD AVX512_KNL AVX512_KNM AVX512_SKX "
                                "AVX512_CLX AVX512_CNL AVX512_ICL AVX512_SPR",
    "OPENBLAS_CORETYPE": "Haswell",
}

#: the CPU features OpenBLAS's Haswell kernels need
_NEEDED = {"avx2", "fma"}
#: the names ``platform.machine()`` gives an x86-64 CPU
_X86_64 = ("x86_64", "amd64")


def cpu_flags(cpuinfo: str = "/proc/cpuinfo") -> Set[str]:
    """The CPU's feature flags as Linux lists them (empty where there is no such file)."""
    try:
        with open(cpuinfo, encoding="utf-8") as f:
            for line in f:
                if line.startswith("flags"):
                    return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


def portable_environment(environ: Optional[Dict[str, str]] = None,
                         flags: Optional[Set[str]] = None,
                         machine: Optional[str] = None) -> Dict[str, str]:
    """The variables :func:`use_portable_arithmetic` would set: those of
    :data:`PORTABLE_ENVIRONMENT` that ``environ`` (default ``os.environ``) does not set
    already; none when ``environ`` has ``PILCO_PORTABLE_ARITHMETIC=0``, on anything but
    Linux on x86-64 (``machine``, default this one's) or on a CPU without AVX2 and FMA
    (``flags``, default :func:`cpu_flags`)."""
    environ = os.environ if environ is None else environ
    if environ.get(SWITCH, "").strip() == "0":
        return {}
    machine = machine if machine is not None else (
        platform.machine() if sys.platform.startswith("linux") else "")
    if machine.lower() not in _X86_64:
        return {}
    if not _NEEDED <= (cpu_flags() if flags is None else flags):
        return {}
    return {k: v for k, v in PORTABLE_ENVIRONMENT.items() if k not in environ}


def use_portable_arithmetic() -> Dict[str, str]:
    """Set :func:`portable_environment`'s variables in ``os.environ`` and return them.
    They act on numpy and OpenBLAS loaded after this call, in this process and in the
    processes it starts."""
    changes = portable_environment()
    os.environ.update(changes)
    return changes


def arithmetic_state() -> Dict[str, Any]:
    """Which paths this process's arithmetic takes: ``numpy_avx512``, the AVX-512 features
    numpy's loops use (empty: its AVX2 paths at most), ``blas``, the kernel sets of the
    BLAS libraries loaded (OpenBLAS's ``Haswell``, ``SkylakeX``, ``Zen``, ...), and
    ``portable``: True when both are the AVX2 paths that every x86-64 CPU with AVX2
    runs alike, False when not, None off x86-64 (imports numpy and ``threadpoolctl``)."""
    import numpy

    try:
        from numpy.core._multiarray_umath import __cpu_features__ as features
    except ImportError:  # another numpy layout: the features are not known
        features = {}
    # the features numpy's AVX-512 loops are chosen by (AVX512F and the AVX512_* groups;
    # the others, AVX512BW, AVX512VL, ..., only describe the CPU)
    avx512 = sorted(name for name, on in features.items()
                    if on and (name == "AVX512F" or name.startswith("AVX512_")))
    try:
        from threadpoolctl import threadpool_info

        blas = sorted({str(info.get("architecture")) for info in threadpool_info()
                       if info.get("user_api") == "blas"})
    except Exception:  # threadpoolctl missing or failing: the kernels are not known
        blas = []
    x86 = platform.machine().lower() in _X86_64
    portable = (not avx512 and all(b.lower() == "haswell" for b in blas)) if x86 else None
    return {"portable": portable, "numpy_avx512": avx512, "blas": blas,
            "numpy": numpy.__version__}


def portability_warning(state: Optional[Dict[str, Any]] = None) -> Optional[str]:
    """A sentence for a process whose arithmetic is its CPU's own although the CPU could
    run the portable paths (``state``: :func:`arithmetic_state`); None otherwise."""
    state = arithmetic_state() if state is None else state
    if state["portable"] is not False or not portable_environment(environ={}):
        return None
    if os.environ.get(SWITCH, "").strip() == "0":
        return None  # asked for
    paths = [f"BLAS kernels {', '.join(state['blas'])}"] if state["blas"] else []
    if state["numpy_avx512"]:
        paths.insert(0, f"numpy's {' '.join(state['numpy_avx512'])} loops")
    return (f"this process runs its CPU's own arithmetic ({'; '.join(paths)}), so a "
            f"seed's run here may differ from the same seed's on another CPU: numpy was "
            f"loaded before "
            f"pilco, or NPY_DISABLE_CPU_FEATURES / OPENBLAS_CORETYPE were set otherwise. "
            f"Import pilco before numpy (or run `pilco run`) for the arithmetic that every "
            f"x86-64 CPU with AVX2 runs alike; {SWITCH}=0 silences this")
