"""Running a sweep's runs on Ray: one Ray task per run, one OS process per task.

A run is ``python -m pilco.tasks TASK --seed S --output RUN_DIR --quiet --no-render
--no-figures FLAGS...`` started by :func:`execute_run` inside a Ray task that reserves
``cpus_per_run`` CPUs and limits TensorFlow's inter-op and the BLAS libraries' thread
pools to as many threads (TensorFlow's intra-op pool to one, see
:func:`pilco.runtime.thread_environment`), so ``C`` CPUs run ``C / cpus_per_run`` runs
side by side without oversubscription. The Ray task returns the run's summary (and the
tails of its output); the driver (:func:`execute`) writes ``summary.json`` and
``sweep-run.json`` into the run directory itself, so results reach the driver's disk
even when the worker's file system is not shared.

A process that exits non-zero or leaves no complete summary raises :class:`RunFailed` in
its Ray task, which Ray retries (``retry_exceptions``), as it retries a task whose worker
died; after ``max_retries`` retries the run is recorded as failed with its exit code and
the last lines of its standard error.

A retry, and a run that an earlier sweep with the same flags left unfinished, continues
from the episodes saved in its directory (the task's ``--resume``): a killed run loses
at most the episode in progress and counts no episode twice.
"""
from __future__ import annotations

import collections
import contextlib
import dataclasses
import functools
import json
import logging
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time

from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple

# nothing here imports TensorFlow (pilco.experiment would): each Ray worker imports this
# module for its task, and only starts and watches a run's process
from pilco.files import write_json_atomic
from pilco.runtime import XLA_CACHE_VARIABLE, signal_handler, thread_environment

__all__ = ["RunSpec", "RunFailed", "SweepOutcome", "SUMMARY", "RUN_RECORD", "ATTEMPTS",
           "PROGRESS", "read_json", "summary_complete", "finished_summary", "saved_episodes",
           "run_environment", "execute_run", "execute"]

logger = logging.getLogger(__name__)

#: a run's summary, written by the run and again by the driver
SUMMARY = "summary.json"
#: the driver's record of a run: command, status, exit code, output tails, node
RUN_RECORD = "sweep-run.json"
#: a run's saved state, written by the run after every episode (what ``--resume`` reads)
PROGRESS = "progress.json"

#: lines of a run's standard error kept in the failure report
TAIL_LINES = 20

#: one line per attempt of a run (the driver clears it when it submits the run)
ATTEMPTS = "attempts.log"


@dataclasses.dataclass(frozen=True)
class RunSpec:
    """One run of a sweep: ``task`` with ``seed`` and ``flags`` (the setting's flags and
    the extra task flags, without the ones the sweep always passes) into ``directory``
    (absolute, on the driver's machine); ``label`` names the setting; ``import_root`` is
    put first on the run's ``PYTHONPATH`` (the directory of a task's module named by
    ``module:ATTRIBUTE``, which the run's process must import)."""

    task: str
    seed: int
    label: str
    flags: Tuple[str, ...]
    directory: str
    import_root: Optional[str] = None

    def command(self, directory: Optional[str] = None) -> List[str]:
        """The run's command line (``directory`` replaces the run directory)."""
        return [sys.executable, "-m", "pilco.tasks", self.task, "--seed", str(self.seed),
                "--output", directory or self.directory, "--quiet", "--no-render",
                "--no-figures", *self.flags]

    @property
    def name(self) -> str:
        return f"{self.label}/seed-{self.seed}"


class RunFailed(Exception):
    """A run's process failed: exit code ``returncode``, last lines of its standard
    error ``stderr_tail``, ``attempt`` (1 for the first) as counted on that node."""

    def __init__(self, message: str, returncode: Optional[int] = None,
                 stderr_tail: str = "", attempt: Optional[int] = None):
        super().__init__(message)
        self.message = message
        self.returncode = returncode
        self.stderr_tail = stderr_tail
        self.attempt = attempt

    def __reduce__(self):  # keep the fields when Ray pickles the exception
        return (type(self), (self.message, self.returncode, self.stderr_tail, self.attempt))

    def __str__(self) -> str:
        return self.message + (f"\n{self.stderr_tail}" if self.stderr_tail else "")


@dataclasses.dataclass
class SweepOutcome:
    """What :func:`execute` did: runs ``finished`` now, ``failed`` (with their error),
    ``not_run`` (left out by an interrupt); ``interrupted`` after Ctrl-C/SIGTERM."""

    finished: List[RunSpec] = dataclasses.field(default_factory=list)
    failed: List[Tuple[RunSpec, Dict[str, Any]]] = dataclasses.field(default_factory=list)
    not_run: List[RunSpec] = dataclasses.field(default_factory=list)
    interrupted: bool = False


def read_json(path: str) -> Optional[Dict[str, Any]]:
    try:
        with open(path, encoding="utf-8") as fh:
            data = json.load(fh)
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def summary_complete(summary: Optional[Mapping[str, Any]]) -> bool:
    """A parsed summary counts as a finished run unless it says ``complete: false``."""
    return summary is not None and bool(summary.get("complete", True))


def finished_summary(spec: RunSpec) -> Optional[Dict[str, Any]]:
    """The complete summary already in ``spec.directory`` (a finished run to skip), or
    None: not for a summary with ``complete: false`` or no episode, nor when the
    directory's ``sweep-run.json`` records a run that did not finish (pending, failed,
    interrupted). A summary without ``sweep-run.json`` (a run started by hand) counts.
    Raises ValueError when the directory holds a run of another task, seed or
    flags, finished or not (the sweep would mix settings)."""
    record = read_json(os.path.join(spec.directory, RUN_RECORD))
    # checked for unfinished runs too: the sweep continues those from their saved episodes
    if record is not None and list(record.get("flags", [])) != list(spec.flags):
        raise ValueError(f"{spec.directory} holds a run made with the flags "
                         f"{' '.join(record.get('flags', [])) or '(none)'}, not "
                         f"{' '.join(spec.flags) or '(none)'}: choose another --output "
                         f"or remove that directory")
    summary = read_json(os.path.join(spec.directory, SUMMARY))
    if not summary_complete(summary) or not summary.get("episodes"):
        return None
    if record is not None and record.get("status") != "finished":
        return None  # what a stopped or failed run left is no result
    if summary.get("task") not in (None, spec.task) or \
            summary.get("seed") not in (None, spec.seed):
        raise ValueError(f"{spec.directory} holds a run of task {summary.get('task')!r} "
                         f"seed {summary.get('seed')!r}, not {spec.task!r} seed {spec.seed}")
    return summary


def saved_episodes(directory: str) -> Optional[int]:
    """The episodes the ``progress.json`` in ``directory`` counts, or None when there is
    no readable one (nothing to resume)."""
    progress = read_json(os.path.join(directory, PROGRESS))
    done = None if progress is None else progress.get("episodes_done")
    if isinstance(done, bool) or not isinstance(done, int) or done < 0:
        return None
    return done


# -------------------------------------------------------------------------- worker side
def _tail(path: str, lines: int = TAIL_LINES) -> str:
    try:
        with open(path, encoding="utf-8", errors="replace") as fh:
            return "".join(collections.deque(fh, maxlen=lines)).rstrip()
    except OSError:
        return ""


def _writable_directory(spec: RunSpec) -> str:
    """``spec.directory`` if it can be created and written here, else the same path
    under this machine's temporary directory (a worker without the driver's disk)."""
    try:
        os.makedirs(spec.directory, exist_ok=True)
        if os.access(spec.directory, os.W_OK):
            return spec.directory
    except OSError:
        pass
    parts = os.path.normpath(spec.directory).split(os.sep)[-3:]
    fallback = os.path.join(tempfile.gettempdir(), "pilco-sweep", *parts)
    os.makedirs(fallback, exist_ok=True)
    return fallback


def _die_with_parent(parent: int) -> None:  # pragma: no cover - in the child before exec
    """Linux: the run gets SIGTERM if its Ray worker (pid ``parent``) dies, instead of
    running on beside the retry; a worker that died before this took effect has left
    the child to another parent already, and the child ends at once."""
    try:
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        return
    if os.getppid() != parent:
        os._exit(1)


def _stop(proc: subprocess.Popen, grace: float = 5.0) -> None:
    """Terminate ``proc`` (SIGTERM, then SIGKILL after ``grace`` seconds)."""
    if proc.poll() is not None:
        return
    proc.terminate()
    try:
        proc.wait(timeout=grace)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def run_environment(threads: int, directory: str,
                    base: Optional[Mapping[str, str]] = None) -> Dict[str, str]:
    """The environment of the run in ``directory`` (``OUTPUT/SETTING/seed-S``): the
    thread pools of :func:`~pilco.runtime.thread_environment`, and ``PILCO_XLA_CACHE``
    set to ``OUTPUT/xla-cache`` unless ``base`` names a cache already, so that the runs
    of a sweep that compile with XLA share one compilation cache."""
    env = thread_environment(threads, base)
    sweep_output = os.path.dirname(os.path.dirname(os.path.abspath(directory)))
    env.setdefault(XLA_CACHE_VARIABLE, os.path.join(sweep_output, "xla-cache"))
    return env


def execute_run(spec: RunSpec, threads: int = 1, resume_saved: bool = False
                ) -> Dict[str, Any]:
    """Run ``spec``'s process with ``threads`` threads and return ``{"summary",
    "stdout_tail", "stderr_tail", "node", "directory", "seconds", "returncode",
    "attempts"}``.

    Its standard output and error go to ``stdout.log`` and ``stderr.log`` in the run
    directory, a line per attempt to ``attempts.log``. The process continues the run
    saved in the directory (``--resume``) when it is a retry (an earlier attempt of this
    submission saved it) or when ``resume_saved`` says that what the directory holds is
    this run's (the driver knows it from the directory's ``sweep-run.json``); otherwise
    it starts afresh. Raises :class:`RunFailed` when the process exits non-zero or leaves
    no complete ``summary.json``. An interrupt (a cancelled Ray task) stops the process.
    """
    start = time.perf_counter()
    directory = _writable_directory(spec)
    with open(os.path.join(directory, ATTEMPTS), "a+", encoding="utf-8") as fh:
        fh.seek(0)
        attempt = sum(1 for _ in fh) + 1
        saved = saved_episodes(directory) if resume_saved or attempt > 1 else None
        fh.write(f"{time.strftime('%Y-%m-%dT%H:%M:%S')} {socket.gethostname()} "
                 f"pid {os.getpid()} "
                 f"{'new run' if saved is None else f'resume after episode {saved}'}\n")
    with contextlib.suppress(FileNotFoundError):
        os.remove(os.path.join(directory, SUMMARY))  # an unfinished run's, never a result
    command = spec.command(directory)
    if saved is not None:
        # the flags given again win over the saved ones, so the run keeps this setting
        command += ["--resume", directory]
    env = run_environment(threads, directory)
    if spec.import_root:
        env["PYTHONPATH"] = os.pathsep.join(
            p for p in (spec.import_root, env.get("PYTHONPATH")) if p)
    out_path = os.path.join(directory, "stdout.log")
    err_path = os.path.join(directory, "stderr.log")
    with open(out_path, "wb") as out, open(err_path, "wb") as err:
        proc = subprocess.Popen(command, stdout=out, stderr=err,
                                stdin=subprocess.DEVNULL, env=env,
                                preexec_fn=functools.partial(_die_with_parent, os.getpid())
                                if sys.platform == "linux" else None)
        try:
            # waits of a second: Ray cancels a task by raising KeyboardInterrupt between
            # two bytecodes, which never happens inside one long blocking wait
            while True:
                try:
                    returncode = proc.wait(timeout=1.0)
                    break
                except subprocess.TimeoutExpired:
                    continue
        except BaseException:
            _stop(proc)
            raise
    stderr_tail = _tail(err_path)
    summary = read_json(os.path.join(directory, SUMMARY))
    if returncode != 0:
        raise RunFailed(f"{spec.name}: exit code {returncode}", returncode, stderr_tail,
                        attempt)
    if not summary_complete(summary):
        raise RunFailed(f"{spec.name}: exit code 0 but "
                        f"{'an incomplete' if summary else 'no'} {SUMMARY}",
                        returncode, stderr_tail, attempt)
    return {"summary": summary, "stdout_tail": _tail(out_path), "stderr_tail": stderr_tail,
            "node": socket.gethostname(), "directory": directory, "returncode": returncode,
            "attempts": attempt, "seconds": time.perf_counter() - start}


# -------------------------------------------------------------------------- driver side
def _record(spec: RunSpec, **fields) -> None:
    write_json_atomic(os.path.join(spec.directory, RUN_RECORD), {
        "task": spec.task, "seed": spec.seed, "setting": spec.label, "flags": list(spec.flags),
        "command": spec.command()[1:], **fields})


def _failure(spec: RunSpec, err: BaseException, attempts: int) -> Dict[str, Any]:
    """``{"error", "returncode", "stderr_tail", "attempts"}`` of a Ray error."""
    cause = getattr(err, "cause", None)
    if isinstance(err, RunFailed):
        cause = err
    if isinstance(cause, RunFailed):
        return {"error": cause.message, "returncode": cause.returncode,
                "stderr_tail": cause.stderr_tail,
                "attempts": attempts if cause.attempt is None else cause.attempt}
    text = str(err).strip().splitlines()
    return {"error": f"{spec.name}: {type(err).__name__}: {text[-1] if text else ''}",
            "returncode": None, "stderr_tail": "\n".join(text[-TAIL_LINES:]),
            "attempts": attempts}


def _sigterm_as_interrupt():
    """SIGTERM raises KeyboardInterrupt in the driver (main thread only)."""
    def handler(signum, frame):  # signal handler signature
        raise KeyboardInterrupt

    return signal_handler(signal.SIGTERM, handler)


def _collect(ref, pending: Dict[Any, RunSpec], outcome: SweepOutcome, max_retries: int,
             on_result: Optional[Callable[[RunSpec, Dict[str, Any]], None]],
             stopped: bool = False) -> None:
    """Record the result of ``ref`` (a finished task) in its run's directory and in
    ``outcome``; once ``stopped``, a failure is the interrupt's and raises instead.
    The run leaves ``pending`` only when it is recorded."""
    import ray

    spec = pending[ref]
    try:
        result = ray.get(ref)
    except (ray.exceptions.RayError, RunFailed) as err:
        if stopped:
            raise
        failure = _failure(spec, err, max_retries + 1)
        _record(spec, status="failed", **failure)
        outcome.failed.append((spec, failure))
        logger.warning("%s failed after %d attempt(s): %s", spec.name,
                       failure["attempts"], failure["error"])
    else:
        summary = result["summary"]
        write_json_atomic(os.path.join(spec.directory, SUMMARY), summary)
        _record(spec, status="finished",
                **{k: v for k, v in result.items() if k != "summary"})
        outcome.finished.append(spec)
        if on_result is not None:
            on_result(spec, summary)
    del pending[ref]


def _submit(remote, specs: Sequence[RunSpec], cpus_per_run: int,
            pending: Dict[Any, RunSpec]) -> None:
    """Submit a Ray task of ``remote`` for every run of ``specs``, each into ``pending``
    as it goes, after recording it pending in its directory."""
    for spec in specs:
        # a record of this run (same task, seed and flags) means that what the
        # directory holds was saved by this run: it continues from there
        old = read_json(os.path.join(spec.directory, RUN_RECORD)) or {}
        resume_saved = (old.get("task"), old.get("seed"), old.get("flags")) == \
            (spec.task, spec.seed, list(spec.flags))
        # until the driver records it finished, whatever the run leaves in
        # its directory (a summary written when it was stopped) is no result
        _record(spec, status="pending")
        with contextlib.suppress(FileNotFoundError):
            os.remove(os.path.join(spec.directory, ATTEMPTS))
        pending[remote.remote(spec, cpus_per_run, resume_saved)] = spec


def _stop_pending(pending: Dict[Any, RunSpec], outcome: SweepOutcome,
                  collect: Callable[..., None]) -> None:
    """After an interrupt: cancel the unfinished tasks, keep the runs that finish within
    a few seconds (``collect(ref, stopped=True)``), record the others interrupted."""
    import ray

    outcome.interrupted = True
    logger.warning("interrupted: cancelling %d unfinished run(s); finished "
                   "runs are kept", len(pending))
    for ref in pending:
        with contextlib.suppress(Exception):
            ray.cancel(ref, force=False)
    # give running tasks a moment to stop their processes; a run that
    # finishes meanwhile is kept as finished
    with contextlib.suppress(Exception, KeyboardInterrupt):
        done, _ = ray.wait(list(pending), num_returns=len(pending),
                           timeout=10.0)
        for ref in done:
            with contextlib.suppress(ray.exceptions.RayError, RunFailed):
                collect(ref, stopped=True)
    outcome.not_run.extend(pending.values())
    for spec in pending.values():
        with contextlib.suppress(OSError):
            _record(spec, status="interrupted")


def execute(specs: Sequence[RunSpec], *, cpus_per_run: int = 1, max_retries: int = 1,
            progress: bool = True,
            on_result: Optional[Callable[[RunSpec, Dict[str, Any]], None]] = None
            ) -> SweepOutcome:
    """Run ``specs`` as Ray tasks on the Ray instance this process is connected to.

    Every finished run's summary and record are written into its directory as results
    arrive; a failed run is recorded with its error after ``max_retries`` retries. On
    Ctrl-C (or SIGTERM) the pending tasks are cancelled, their processes stopped, and the
    outcome returned with ``interrupted=True``.
    """
    import ray
    from tqdm.auto import tqdm

    if isinstance(cpus_per_run, bool) or not isinstance(cpus_per_run, int) or cpus_per_run < 1:
        raise ValueError(f"cpus_per_run must be a positive integer, got {cpus_per_run!r}")
    if isinstance(max_retries, bool) or not isinstance(max_retries, int) or max_retries < 0:
        raise ValueError(f"max_retries must be a non-negative integer, got {max_retries!r}")
    if not ray.is_initialized():
        raise RuntimeError("execute() needs a Ray connection: call ray.init() first")
    remote = ray.remote(execute_run).options(num_cpus=cpus_per_run, max_retries=max_retries,
                                             retry_exceptions=True)
    outcome = SweepOutcome()
    pending: Dict[Any, RunSpec] = {}
    collect = functools.partial(_collect, pending=pending, outcome=outcome,
                                max_retries=max_retries, on_result=on_result)
    bar = tqdm(total=len(specs), unit="run", desc="sweep", file=sys.stderr,
               disable=not progress, dynamic_ncols=True)
    try:
        with _sigterm_as_interrupt():
            try:
                _submit(remote, specs, cpus_per_run, pending)
                while pending:
                    done, _ = ray.wait(list(pending), num_returns=1, timeout=1.0)
                    for ref in done:
                        collect(ref)
                        bar.update(1)
            except KeyboardInterrupt:
                _stop_pending(pending, outcome, collect)
    finally:
        bar.close()
    return outcome
