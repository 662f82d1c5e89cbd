"""Start-up of pilco's command-line entry points: TensorFlow's log lines, logging, threads,
XLA's compilation cache, a signal's handler for the length of a block.

Every command (``pilco``, ``python -m pilco.tasks``, ``python -m pilco.sweep``,
``python -m pilco.diagnose``) calls :func:`quiet_tensorflow` before anything imports
TensorFlow, sets up logging with :func:`configure_logging` and the thread pools with
:func:`configure_threads` (a process of its own) or :func:`thread_environment` (the
environment of a process it starts). A run that compiles its policy objective with XLA
calls :func:`use_xla_cache`, so that the runs of a sweep (or a user's runs one after
another) compile each data-size bucket once.

Nothing here imports TensorFlow at import time.
"""
from __future__ import annotations

import contextlib
import importlib.abc
import logging
import os
import re
import signal
import sys
import tempfile
from typing import Dict, Iterator, List, Mapping, Optional, Union

__all__ = ["TF_LOG_LEVEL", "THREAD_VARIABLES", "quiet_tensorflow", "log_level",
           "configure_logging", "limit_blas_threads", "ARITHMETIC_OPTIMIZER_VARIABLE",
           "reproducible_arithmetic",
           "configure_threads",
           "thread_environment", "XLA_CACHE_VARIABLE",
           "xla_cache_directory", "use_xla_cache", "signal_handler"]

#: ``TF_CPP_MIN_LOG_LEVEL`` unless it is set: TensorFlow's C++ INFO and WARNING lines
#: are hidden (they drown the progress output; pilco logs through :mod:`logging`)
TF_LOG_LEVEL = "2"

#: environment variables that size TensorFlow's and the BLAS libraries' thread pools
THREAD_VARIABLES = ("TF_NUM_INTRAOP_THREADS", "TF_NUM_INTEROP_THREADS", "OMP_NUM_THREADS",
                    "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")

#: environment variable that, set to ``1``, leaves Grappler's arithmetic optimizer on
#: (:func:`reproducible_arithmetic`)
ARITHMETIC_OPTIMIZER_VARIABLE = "PILCO_ARITHMETIC_OPTIMIZER"

#: environment variable naming the folder of XLA's persistent compilation cache (a sweep
#: sets it to a folder in its output directory, shared by its runs)
XLA_CACHE_VARIABLE = "PILCO_XLA_CACHE"
_XLA_CACHE_FLAG = "--tf_xla_persistent_cache_directory"

LOG_FORMAT = "%(asctime)s %(name)s %(levelname)s: %(message)s"

# ------------------------------------------------------------------ TensorFlow's probe
# What TensorFlow writes to file descriptor 2 on a machine without CUDA. The drivers
# line comes from the CUDA runtime stub at ``import tensorflow`` whatever
# TF_CPP_MIN_LOG_LEVEL says; the cuInit line when the devices are first listed (hidden
# by TF_CPP_MIN_LOG_LEVEL=3 only); the factory lines from builds that register their
# CUDA libraries twice.
_NO_DRIVERS = re.compile(rb"Could not find cuda drivers on your machine, GPU will not be used")
_CUINIT = re.compile(rb"failed call to cuInit")
_FACTORY = re.compile(rb"Unable to register cu[A-Za-z]+ factory")
# absl's note before its first log line; dropped with the line it introduces
_ABSL_NOTE = re.compile(rb"^WARNING: All log messages before absl::InitializeLog\(\) is called "
                        rb"are written to STDERR\s*$")
# A line in absl's format ("I0000 00:00:1700000000.000000    1234 port.cc:153] ..."): its
# first letter is the severity. Some are written before TensorFlow's logging has read
# TF_CPP_MIN_LOG_LEVEL (oneDNN's "custom operations are on" notice on CPUs where oneDNN is
# on by default), so the level does not hide them.
_ABSL_LINE = re.compile(rb"^([IWEF])\d{4} \d+:\d+:\d+\.\d+\s+\d+ [^\]\s]+\] ")
_SEVERITY = {b"I": 0, b"W": 1, b"E": 2, b"F": 3}


def _below_level(line: bytes, level: int) -> bool:
    """Whether ``line`` is an absl-format line of a severity that ``TF_CPP_MIN_LOG_LEVEL
    = level`` hides (INFO below 1, WARNING below 2, ERROR below 3)."""
    match = _ABSL_LINE.match(line)
    return bool(match) and _SEVERITY[match.group(1)] < level


def _log_level_setting() -> int:
    """``TF_CPP_MIN_LOG_LEVEL`` as a number (0 when unset or not a whole number)."""
    try:
        return int(os.environ.get("TF_CPP_MIN_LOG_LEVEL", "0").strip())
    except ValueError:
        return 0


def _probe_lines(lines: List[bytes], level: int = 0) -> List[bool]:
    """Which of ``lines`` (stderr written during TensorFlow's import) to drop: its CUDA
    probe (the no-drivers and factory lines, the cuInit failure when the same import
    reported no drivers: on a machine with drivers that failure is a real error), the
    absl-format lines that ``TF_CPP_MIN_LOG_LEVEL = level`` hides (:func:`_below_level`),
    and absl's note right before a line so dropped."""
    no_drivers = any(_NO_DRIVERS.search(line) for line in lines)
    drop = [bool(_NO_DRIVERS.search(line) or _FACTORY.search(line)
                 or (no_drivers and _CUINIT.search(line)) or _below_level(line, level))
            for line in lines]
    for i in range(len(lines) - 1):
        if not drop[i] and drop[i + 1] and _ABSL_NOTE.match(lines[i]):
            drop[i] = True
    return drop


def _write_all(fd: int, data: bytes) -> None:
    while data:
        data = data[os.write(fd, data):]


def _flush_python_stderr() -> None:
    for stream in (sys.stderr, sys.__stderr__):
        with contextlib.suppress(Exception):
            stream.flush()


@contextlib.contextmanager
def _stderr_without_probe_lines() -> Iterator[None]:
    """File descriptor 2 goes to a temporary file inside the block; afterwards, also
    when the block raises, fd 2 is restored and every line written meanwhile is written
    to it again except TensorFlow's CUDA probe lines (:func:`_probe_lines`). A temporary
    file rather than a pipe: it never fills up, so nothing the block writes can block it.
    If fd 2 cannot be redirected (closed, no temporary file), the block runs as is."""
    _flush_python_stderr()
    try:
        capture = tempfile.TemporaryFile()
    except OSError:
        yield
        return
    try:
        saved = os.dup(2)
    except OSError:
        capture.close()
        yield
        return
    try:
        os.dup2(capture.fileno(), 2)
        try:
            yield
        finally:
            _flush_python_stderr()
            os.dup2(saved, 2)
    finally:
        os.close(saved)
        try:
            capture.seek(0)
            lines = capture.read().splitlines(keepends=True)
        finally:
            capture.close()
        drop = _probe_lines(lines, _log_level_setting())
        with contextlib.suppress(OSError):  # a closed stderr must not mask the import's error
            _write_all(2, b"".join(line for line, gone in zip(lines, drop) if not gone))


class _FilteredLoader(importlib.abc.Loader):
    """TensorFlow's own loader, run by :func:`_stderr_without_probe_lines` and followed
    there by a listing of the devices (which makes TensorFlow probe CUDA now, inside the
    filter, rather than at its first operation). The listing leaves every setting that
    must precede TensorFlow's start (threads, visible devices) still open."""

    def __init__(self, loader, finder: "_TensorFlowImportFilter"):
        self._loader = loader
        self._finder = finder

    def create_module(self, spec):
        return self._loader.create_module(spec)

    def exec_module(self, module) -> None:
        # the module keeps its own loader for everything after this import
        module.__loader__ = self._loader
        if getattr(module, "__spec__", None) is not None:
            module.__spec__.loader = self._loader
        self._finder.done = True
        with _stderr_without_probe_lines():
            self._loader.exec_module(module)
            with contextlib.suppress(Exception):  # quieting must never break an import
                module.config.list_physical_devices("GPU")


class _TensorFlowImportFilter(importlib.abc.MetaPathFinder):
    """Finds ``tensorflow`` as the finders after it do, with :class:`_FilteredLoader` as
    its loader; every other module, and ``tensorflow`` once imported, are left to them."""

    def __init__(self) -> None:
        self.done = False

    def find_spec(self, fullname, path=None, target=None):
        if fullname != "tensorflow" or self.done:
            return None
        for finder in list(sys.meta_path):
            if finder is self or not hasattr(finder, "find_spec"):
                continue
            spec = finder.find_spec(fullname, path, target)
            if spec is not None:
                break
        else:
            return None
        if spec.loader is not None and hasattr(spec.loader, "exec_module"):
            spec.loader = _FilteredLoader(spec.loader, self)
        return spec


def quiet_tensorflow() -> None:
    """Quiet TensorFlow's start-up on stderr; call before anything imports TensorFlow.

    Sets ``TF_CPP_MIN_LOG_LEVEL`` to :data:`TF_LOG_LEVEL` unless it is set (processes
    started from here inherit it), and makes the first ``import tensorflow`` (now or
    later, wherever it happens) run with file descriptor 2 redirected, then write back
    everything it wrote except the CUDA probe lines of a machine without CUDA ("Could
    not find cuda drivers on your machine, GPU will not be used.", which no log level
    hides, "failed call to cuInit", "Unable to register cuDNN/cuFFT/cuBLAS factory") and
    the lines of a severity the level hides that are written before TensorFlow reads it
    (oneDNN's "custom operations are on" notice).
    Other output of the import, a traceback included, is written back in full once the
    import ends (a process killed during the import loses it). A process that does not
    import TensorFlow pays nothing.

    Does nothing when TensorFlow is imported already, nor when ``TF_CPP_MIN_LOG_LEVEL``
    is ``0`` (asked for TensorFlow's every line). Calling it again does nothing more.
    """
    if "tensorflow" in sys.modules:
        return
    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", TF_LOG_LEVEL)
    if os.environ["TF_CPP_MIN_LOG_LEVEL"].strip() == "0":
        return
    if not any(isinstance(f, _TensorFlowImportFilter) for f in sys.meta_path):
        sys.meta_path.insert(0, _TensorFlowImportFilter())


# ----------------------------------------------------------------------------- logging
def log_level(level: Union[str, int]) -> int:
    """The :mod:`logging` level named by ``level`` (``"warning"``, ``"INFO"``; any case),
    or ``level`` itself when it is an integer. ValueError naming ``level`` for anything
    else; also fit as an argparse ``type=``."""
    if isinstance(level, int) and not isinstance(level, bool):
        return level
    value = logging.getLevelName(str(level).strip().upper())
    if not isinstance(value, int):
        names = ", ".join(logging.getLevelName(n) for n in (logging.DEBUG, logging.INFO,
                                                             logging.WARNING, logging.ERROR,
                                                             logging.CRITICAL))
        raise ValueError(f"unknown logging level {level!r}; choose one of {names}")
    return value


def configure_logging(level: Union[str, int], logger: Optional[str] = None) -> None:
    """Log to stderr (``logging.basicConfig``, lines "time name LEVEL: message") at
    ``level`` (:func:`log_level`: a name in any case, or a number; ValueError naming a
    bad one). With ``logger`` (e.g. ``"pilco"``) only that logger gets ``level`` and the
    others stay at WARNING (the libraries a command uses keep their INFO lines to
    themselves). Like ``basicConfig``, adds no handler when the root logger has one."""
    value = log_level(level)
    if logger is None:
        logging.basicConfig(level=value, format=LOG_FORMAT)
    else:
        logging.basicConfig(level=logging.WARNING, format=LOG_FORMAT)
        logging.getLogger(logger).setLevel(value)


# ----------------------------------------------------------------------------- threads
def _positive(threads) -> int:
    if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
        raise ValueError(f"threads must be a positive integer, got {threads!r}")
    return threads


def limit_blas_threads() -> None:
    """One thread for the BLAS libraries loaded in this process (numpy's and scipy's
    OpenBLAS or MKL, through ``threadpoolctl``), whatever ``OMP_NUM_THREADS`` or
    ``OPENBLAS_NUM_THREADS`` said when they were loaded. Their work here is small (the
    policy search's BFGS updates, GP training's L-BFGS-B), but a product split over
    threads sums in another order: with two threads a run's rounding, and so its path,
    differs from the same run's with one, as a sweep gives it."""
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=1, user_api="blas")


def reproducible_arithmetic() -> None:
    """Turn off Grappler's arithmetic optimizer (``tf.config.optimizer``) for the functions
    this process traces from now on, so that a compiled function gives the same bits in
    every process.

    With it on, the policy objective's gradient (a ``tf.while_loop`` over the horizon)
    depends on how TensorFlow's executor happens to schedule the loop's operations: the
    same objective on the same inputs gives a gradient differing in the last bits in some
    evaluations, mostly the first ones of a process, whether the inter-op pool has one
    thread or several, with oneDNN on or off and with TensorFlow's op determinism; a run
    then takes another path from one process to the next. With it off the value and
    gradient are the same in every process, with one inter-op thread (a sweep's run) or
    several (a run alone), on both oneDNN paths, at the same speed (docs/success-rates.md,
    "Runs that part"). Without the optimizer's rewrites (additions regrouped, common
    factors hoisted) each operation runs as written. Affects the whole process
    (TensorFlow has one such setting); imports TensorFlow.

    ``PILCO_ARITHMETIC_OPTIMIZER=1`` in the environment leaves the optimizer on (runs
    then round as before this switch, and part between processes), e.g. to compare the
    two arithmetics' success rates in a sweep, whose runs inherit the variable.
    """
    if os.environ.get(ARITHMETIC_OPTIMIZER_VARIABLE, "") == "1":
        return
    import tensorflow as tf

    tf.config.optimizer.set_experimental_options({"arithmetic_optimization": False})


def configure_threads(threads: Optional[int] = None) -> None:
    """Size this process's TensorFlow thread pools, and the BLAS libraries' to one thread
    (:func:`limit_blas_threads`), and make its compiled functions' arithmetic independent
    of scheduling (:func:`reproducible_arithmetic`), so that a seed gives the same run
    alone and in a sweep, in every process.

    ``None`` (a task's process): one intra-op thread unless ``TF_NUM_INTRAOP_THREADS``
    says otherwise (the inter-op pool keeps its default, every CPU): an operation then
    computes the same bits whatever the CPUs, and independent parts of the graph still
    run side by side (with ``PILCO_PAIR_GROUPS=threads`` also the policy objective's
    groups of output pairs, :func:`pilco.moments.pair_groups`: faster on several CPUs,
    but rounded as their number says; docs/performance.md). Takes effect in a process
    that has not run a TensorFlow operation yet.

    ``threads`` (``python -m pilco.diagnose --threads N``): ``threads`` intra- and
    inter-op threads through ``tf.config.threading`` (imports TensorFlow; before its
    first operation, else TensorFlow raises RuntimeError).
    """
    if threads is None:
        os.environ.setdefault("TF_NUM_INTRAOP_THREADS", "1")
    else:
        threads = _positive(threads)
    limit_blas_threads()
    reproducible_arithmetic()
    if threads is None:
        return
    import tensorflow as tf

    tf.config.threading.set_intra_op_parallelism_threads(threads)
    tf.config.threading.set_inter_op_parallelism_threads(threads)


def thread_environment(threads: int, base: Optional[Mapping[str, str]] = None
                       ) -> Dict[str, str]:
    """The environment of a process given ``threads`` CPUs (a sweep's run): ``base``
    (default ``os.environ``) with TensorFlow's inter-op pool and the OpenMP/OpenBLAS/MKL
    pools set to ``threads`` threads and TensorFlow's intra-op pool to one (as
    :func:`configure_threads`, for the same reason), ``TF_CPP_MIN_LOG_LEVEL`` to
    :data:`TF_LOG_LEVEL` unless set. ValueError unless ``threads`` is a positive
    integer."""
    threads = _positive(threads)
    env = dict(os.environ if base is None else base)
    env.update({name: str(threads) for name in THREAD_VARIABLES})
    env["TF_NUM_INTRAOP_THREADS"] = "1"
    env.setdefault("TF_CPP_MIN_LOG_LEVEL", TF_LOG_LEVEL)
    return env


def xla_cache_directory(environ: Optional[Mapping[str, str]] = None) -> str:
    """The folder of XLA's persistent compilation cache: ``$PILCO_XLA_CACHE`` if set,
    else ``pilco/xla`` in the user's cache folder (``$XDG_CACHE_HOME``, default
    ``~/.cache``)."""
    env = os.environ if environ is None else environ
    if env.get(XLA_CACHE_VARIABLE):
        return os.path.abspath(os.path.expanduser(env[XLA_CACHE_VARIABLE]))
    base = env.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "pilco", "xla")


def use_xla_cache(directory: Optional[str] = None) -> Optional[str]:
    """Make this process's XLA compilations go through a persistent cache in
    ``directory`` (default :func:`xla_cache_directory`): a program compiled by an
    earlier run (same graph, same shapes, same CPU) is loaded instead of compiled again.

    Adds ``--tf_xla_persistent_cache_directory`` to ``TF_XLA_FLAGS``, which TensorFlow
    reads at its first XLA compilation, so call it before that; a cache folder already
    named there is kept. Returns the folder in use, or None (with a warning) if it cannot
    be created: the run then compiles without a cache.
    """
    flags = os.environ.get("TF_XLA_FLAGS", "")
    if _XLA_CACHE_FLAG in flags:
        match = re.search(re.escape(_XLA_CACHE_FLAG) + r"=(\S+)", flags)
        return match.group(1) if match else None
    directory = xla_cache_directory() if directory is None else directory
    try:
        os.makedirs(directory, exist_ok=True)
    except OSError as err:
        logging.getLogger(__name__).warning(
            "XLA compilation cache %s cannot be created (%s); compiling without it",
            directory, err)
        return None
    os.environ["TF_XLA_FLAGS"] = f"{flags} {_XLA_CACHE_FLAG}={directory}".strip()
    return directory


# ----------------------------------------------------------------------------- signals
@contextlib.contextmanager
def signal_handler(signum: int, handler) -> Iterator[None]:
    """Within the block, ``handler`` handles ``signum``; the previous handler is restored
    afterwards. Only the main thread can install handlers; elsewhere this does nothing.
    (Here, not in :mod:`pilco.experiment.signals`, which uses it too: the sweep's Ray
    workers import :mod:`pilco.sweep.runs`, which uses it, and must not import
    :mod:`pilco.experiment`, whose package imports TensorFlow.)"""
    try:
        previous = signal.signal(signum, handler)
    except ValueError:  # not the main thread
        yield
        return
    try:
        yield
    finally:
        signal.signal(signum, previous)
