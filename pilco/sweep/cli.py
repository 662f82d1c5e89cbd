"""``python -m pilco.sweep TASK --seeds 0-19 ...``: many seeds (and settings) of a task on
Ray, then success rates, quartiles and figures.

Every argument is checked before Ray starts: the task name, the seed list, the ``--set``
and ``--grid`` assignments, the form of ``--address`` and, when the task's parser can be
built, every flag a run will get (so a typo fails in a second, not in twenty processes).

Without ``--address`` the sweep starts a Ray of its own, whatever Ray runs (or ran) on
the machine. A cluster named by ``--address`` must accept a connection within
:data:`CONNECT_TIMEOUT` seconds, or the sweep stops with a message naming it. The sweep
holds an exclusive lock on ``DIR/sweep.lock`` while it runs: a second sweep into the same
directory stops at once instead of writing alongside it (the kernel releases the lock
when the holder exits, even when it is killed).
"""
from __future__ import annotations

import argparse
import contextlib
import importlib
import inspect
import itertools
import logging
import os
import re
import socket
import sys
import time
from typing import Any, Dict, List, Optional, Sequence, Tuple

from pilco.files import write_json_atomic

from . import aggregate, figures, runs
from .runs import RunSpec

__all__ = ["DEFAULT_TASKS", "CONNECT_TIMEOUT", "LOCK_FILE", "SweepError", "task_names",
           "task_parser", "parse_seeds", "parse_assignment", "setting_flags", "build_parser",
           "split_address", "check_ray_address", "lock_output", "plan", "main"]

logger = logging.getLogger("pilco.sweep")

#: the tasks when :mod:`pilco.tasks` does not list them itself
DEFAULT_TASKS = ("cartpole", "reacher", "damaged_reacher", "adaptation", "pendulum")

#: flags the sweep passes to every run itself (``--set``/``--grid`` keys may not name them)
RESERVED = ("seed", "output", "resume", "quiet", "no_render", "no_figures", "help")

#: seconds a Ray cluster named by --address has to accept a connection
CONNECT_TIMEOUT = 5.0

#: the file in the sweep directory that a running sweep holds locked
LOCK_FILE = "sweep.lock"

#: Ray's default ports: the head's GCS (HOST:PORT addresses) and the Ray client server
RAY_CLIENT_PORT = 10001

_KEY = re.compile(r"^[A-Za-z][A-Za-z0-9_-]*$")
_TRUE, _FALSE = ("true", "yes", "on", "1"), ("false", "no", "off", "0")
_HOST_PORT = re.compile(r"^(?:\[(?P<ip6>[0-9A-Fa-f:.]+)\]|(?P<host>[A-Za-z0-9_.-]+))"
                        r"(?::(?P<port>\d+))?$")


class SweepError(Exception):
    """A sweep that cannot start: its directory is in use, its Ray cluster does not answer."""


def task_names() -> Tuple[str, ...]:
    """The task names of :data:`pilco.tasks.TASKS` (its keys), else :data:`DEFAULT_TASKS`."""
    try:
        tasks = importlib.import_module("pilco.tasks").TASKS
    except (ImportError, AttributeError):
        return DEFAULT_TASKS
    return tuple(tasks)


def task_parser(task: str) -> Optional[argparse.ArgumentParser]:
    """The argument parser of ``task`` when it can be built here, else None (the runs
    then report unknown flags themselves).

    Uses ``pilco.tasks.build_parser(task)`` if that exists, else the task module's
    ``build_parser`` named by ``pilco.tasks.TASKS[task] = (module, main keyword
    arguments)`` (the arguments ``build_parser`` accepts are passed on).
    """
    try:
        tasks = importlib.import_module("pilco.tasks")
        builder = getattr(tasks, "build_parser", None)
        if callable(builder):
            return builder(task)
        entry = tasks.TASKS[task]
        module_name, kwargs = entry
        module = importlib.import_module(f"pilco.tasks.{module_name}")
        build = module.build_parser
        accepted = inspect.signature(build).parameters
        return build(**{k: v for k, v in dict(kwargs).items() if k in accepted})
    except Exception as err:  # noqa: BLE001 - validation is a convenience, never a blocker
        logger.debug("no parser for task %s (%s): flags are checked by the runs", task, err)
        return None


def parse_seeds(text: str) -> List[int]:
    """``"0-19"``, ``"0,3,5"`` or a mixture (``"0-4,10,12-13"``) -> sorted distinct seeds."""
    seeds = set()
    if not isinstance(text, str) or not text.strip():
        raise ValueError("empty seed list")
    for part in text.split(","):
        part = part.strip()
        m = re.fullmatch(r"(\d+)(?:-(\d+))?", part)
        if not m:
            raise ValueError(f"bad seed or range {part!r} (use e.g. 0-19, 0,3,5 or 0-4,10)")
        first = int(m.group(1))
        last = int(m.group(2)) if m.group(2) is not None else first
        if last < first:
            raise ValueError(f"seed range {part!r} runs backwards")
        if last >= 2 ** 31:
            raise ValueError(f"seed {last} too large (at most {2 ** 31 - 1})")
        seeds.update(range(first, last + 1))
    return sorted(seeds)


def parse_assignment(text: str, grid: bool = False) -> Tuple[str, Any]:
    """``"KEY=VALUE"`` -> ``(key, value)``; with ``grid``, ``"KEY=V1,V2"`` -> ``(key,
    [v1, v2])``. Keys use underscores or dashes (``no_early_stop`` is ``--no-early-stop``)."""
    if "=" not in text:
        raise ValueError(f"{text!r} is not KEY=VALUE")
    key, value = text.split("=", 1)
    key = key.strip().lstrip("-").replace("-", "_")
    if not _KEY.match(key):
        raise ValueError(f"bad key {key!r} in {text!r}")
    if key in RESERVED:
        raise ValueError(f"--{key.replace('_', '-')} is set by the sweep itself")
    if not grid:
        if value == "":
            raise ValueError(f"no value in {text!r}")
        return key, value
    values = value.split(",")
    if any(v == "" for v in values):
        raise ValueError(f"empty value in {text!r}")
    if len(set(values)) != len(values):
        raise ValueError(f"repeated value in {text!r}")
    return key, values


def _option(key: str) -> str:
    return "--" + key.replace("_", "-")


def setting_flags(key: str, value: str, parser: Optional[argparse.ArgumentParser]
                  ) -> List[str]:
    """The task flags of ``key=value``: ``["--key", value]``, or for a flag without value
    (``store_true``) ``["--key"]`` when ``value`` is true and ``[]`` when false (for an
    ``--key/--no-key`` flag ``["--no-key"]``).

    With a ``parser`` the flag must be one of its options. Without one, ``true`` and
    ``false`` are taken as such a flag.
    """
    option = _option(key)
    if parser is not None:
        action = next((a for a in parser._actions  # noqa: SLF001 - argparse has no API
                       if option in a.option_strings), None)
        if action is None:
            raise ValueError(f"the task has no flag {option} (from {key}={value}); see "
                             f"python -m pilco.tasks TASK --help")
        if action.nargs != 0:
            return [option, value]
        if isinstance(action, argparse.BooleanOptionalAction) and value.lower() in _FALSE:
            return ["--no-" + option[2:]]  # a flag that is on by default
    if value.lower() in _TRUE:
        return [option]
    if value.lower() in _FALSE:
        return []
    if parser is not None:
        raise ValueError(f"{option} takes no value: write {key}=true or {key}=false")
    return [option, value]


def _label(items: Sequence[Tuple[str, str]]) -> str:
    if not items:
        return "default"
    text = ",".join(f"{k}={v}" for k, v in items)
    return re.sub(r"[^A-Za-z0-9._=,+-]", "_", text)


def settings(fixed: Sequence[Tuple[str, str]], grid: Sequence[Tuple[str, List[str]]],
             parser: Optional[argparse.ArgumentParser]) -> List[Tuple[str, List[str]]]:
    """``[(label, flags)]``: one setting per combination of the ``grid`` values, each
    with the ``fixed`` assignments; label ``default`` without any."""
    keys = [k for k, _ in fixed] + [k for k, _ in grid]
    repeated = sorted({k for k in keys if keys.count(k) > 1})
    if repeated:
        raise ValueError(f"key(s) given more than once in --set/--grid: {', '.join(repeated)}")
    out = []
    for combo in itertools.product(*[values for _, values in grid]):
        items = list(fixed) + [(k, v) for (k, _), v in zip(grid, combo)]
        flags = [f for k, v in items for f in setting_flags(k, v, parser)]
        out.append((_label(items), flags))
    labels = [label for label, _ in out]
    if len(set(labels)) != len(labels):
        raise ValueError("two settings get the same directory name; use plainer values")
    return out


class _TaskFlagError(Exception):
    pass


def check_task_flags(parser: argparse.ArgumentParser, flags: Sequence[str]) -> None:
    """Parse ``flags`` (as a run gets them) with the task's ``parser``; ValueError with
    the parser's message when it rejects them."""
    def fail(message: str = "", *_, **__):
        raise _TaskFlagError(message)

    parser.error = fail  # the parser is ours: no usage print, no exit
    parser.exit = fail
    try:
        parser.parse_args(["--seed", "0", "--output", "x", "--quiet", "--no-render",
                           "--no-figures", *flags])
    except _TaskFlagError as err:
        raise ValueError(str(err)) from None


def split_address(address: str) -> Optional[Tuple[str, int]]:
    """``(host, port)`` that ``--address`` connects to: ``HOST:PORT`` (a head's GCS port)
    or ``ray://HOST[:PORT]`` (the Ray client, port 10001 by default); None for ``auto``,
    ``local`` and other ``SCHEME://`` addresses (left to Ray). ValueError for anything
    else."""
    if not isinstance(address, str) or not address.strip():
        raise ValueError(f"--address must be auto, HOST:PORT or ray://HOST[:PORT], "
                         f"got {address!r}")
    if address in ("auto", "local"):
        return None
    scheme, sep, rest = address.partition("://")
    if sep and scheme != "ray":
        return None  # a Ray client plug-in's scheme: Ray checks it
    m = _HOST_PORT.match(rest if sep else address)
    if m is None or (not sep and m.group("port") is None):
        raise ValueError(f"--address must be auto, HOST:PORT or ray://HOST[:PORT], "
                         f"got {address!r}")
    port = int(m.group("port")) if m.group("port") is not None else RAY_CLIENT_PORT
    if not 0 < port < 65536:
        raise ValueError(f"--address {address}: port {port} is not in 1-65535")
    return m.group("ip6") or m.group("host"), port


def _ray_address_file() -> str:
    """The file in which ``ray start --head`` records its address (Ray's temporary
    folder: ``$RAY_TMPDIR/ray``, on Linux else ``$TMPDIR/ray``, else ``/tmp/ray``)."""
    try:
        from ray._common.utils import get_ray_address_file  # Ray's own rule

        return get_ray_address_file(None)
    except Exception:  # noqa: BLE001 - an older or newer Ray: the same rule, by hand
        base = os.environ.get("RAY_TMPDIR") or (
            os.environ.get("TMPDIR") if sys.platform.startswith("linux") else None) or "/tmp"
        return os.path.join(base, "ray", "ray_current_cluster")


def _auto_address() -> Tuple[Optional[str], str]:
    """What ``--address auto`` connects to first, as Ray finds it: ``RAY_ADDRESS``, else
    the address recorded by the last ``ray start --head`` here; ``(None, "")`` when
    neither is set (Ray then looks for any Ray process on the machine)."""
    env = os.environ.get("RAY_ADDRESS", "").strip()
    if env:
        return env, "the RAY_ADDRESS environment variable"
    path = _ray_address_file()
    try:
        with open(path, encoding="utf-8") as fh:
            recorded = fh.read().strip()
    except OSError:
        return None, ""
    return (recorded, path) if recorded else (None, "")


def check_ray_address(address: Optional[str], timeout: float = CONNECT_TIMEOUT) -> None:
    """Raise :class:`SweepError` unless the Ray cluster ``address`` names accepts a TCP
    connection within ``timeout`` seconds (``ray.init`` would wait for minutes on a
    cluster that is gone). ``None``/``local`` (a Ray of the sweep's own) pass; ``auto``
    checks the address Ray would take (``RAY_ADDRESS`` or the one recorded by ``ray
    start``), so a stopped head's stale record fails here."""
    if address in (None, "local"):
        return
    target, source = (address, "") if address != "auto" else _auto_address()
    if target is None:
        return  # ray.init(address="auto") looks for a running Ray itself
    try:
        where = split_address(target)
    except ValueError as err:
        raise SweepError(f"--address {address}: {target!r} from {source} is no Ray "
                         f"address ({err})") from None
    if where is None:
        return
    host, port = where
    try:
        with socket.create_connection((host, port), timeout=timeout):
            pass
    except OSError as err:
        reason = f"no answer within {timeout:g} s" if isinstance(err, socket.timeout) \
            else (err.strerror or str(err))
        named = f"{target} (recorded in {source})" if source else target
        advice = ("that cluster has stopped: start one with `ray start --head`, or "
                  f"remove {source}" if source.endswith("ray_current_cluster") else
                  "is the cluster running and its port open from here?")
        raise SweepError(f"--address {address}: no Ray cluster answers at {named}: "
                         f"{reason}; {advice}; or leave out --address for a Ray of the "
                         f"sweep's own") from None


def lock_output(directory: str):
    """Hold an exclusive lock on ``directory``/``sweep.lock`` (created with the directory)
    and return its open file: the lock lasts until that file is closed or the process
    ends, however it ends. :class:`SweepError` naming the holder when another process
    holds it."""
    os.makedirs(directory, exist_ok=True)
    path = os.path.join(directory, LOCK_FILE)
    fh = open(path, "a+", encoding="utf-8")
    try:
        import fcntl
    except ImportError:  # no flock (Windows): no protection, say so
        logger.warning("cannot lock %s on this system: do not start a second sweep into "
                       "it", directory)
        return fh
    try:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        fh.seek(0)
        holder = fh.read().strip() or "a process"
        fh.close()
        raise SweepError(f"another sweep ({holder}) is running in {directory}: wait for "
                         f"it to end, or choose another --output") from None
    fh.seek(0)
    fh.truncate()
    fh.write(f"pid {os.getpid()} on {socket.gethostname()} since "
             f"{time.strftime('%Y-%m-%dT%H:%M:%S')}\n")
    fh.flush()
    return fh


def build_parser() -> argparse.ArgumentParser:
    tasks = task_names()
    parser = argparse.ArgumentParser(
        prog="python -m pilco.sweep",
        usage="%(prog)s TASK [--seeds SEEDS] [options] [-- TASK FLAGS...]",
        description="Run a PILCO task for many seeds (and settings) on Ray; report success\n"
                    "rates with 95 % Wilson intervals, episodes to solve, distances, times.\n"
                    "Each run is `python -m pilco.tasks TASK --seed S --output\n"
                    "DIR/SETTING/seed-S --quiet --no-render --no-figures [setting flags]\n"
                    "[TASK FLAGS]`. The same command again skips the runs that finished.",
        epilog="examples:\n"
               "  python -m pilco.sweep cartpole --seeds 0-19\n"
               "  python -m pilco.sweep reacher --seeds 0-9 --grid cost_width=0.2,0.3\n"
               "  python -m pilco.sweep pendulum --seeds 0-9\n"
               "  python -m pilco.sweep cartpole --seeds 0,3,5 --set no_early_stop=true "
               "-- --episodes 10\n"
               "  python -m pilco.sweep cartpole --seeds 0-99 --address auto "
               "--cpus-per-run 2",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("task", metavar="TASK", help=f"one of: {', '.join(tasks)}")
    parser.add_argument("--seeds", default="0-9",
                        help="seeds: a range 0-19, a list 0,3,5 or both (default 0-9)")
    parser.add_argument("--output", metavar="DIR", default=None,
                        help="sweep directory (default runs/sweep-TASK): runs go to "
                             "DIR/SETTING/seed-S, the aggregate to DIR/sweep.json")
    parser.add_argument("--set", dest="fixed", metavar="KEY=VALUE", action="append",
                        default=[], help="a task flag for every run: horizon=30 is "
                                         "--horizon 30, no_early_stop=true is "
                                         "--no-early-stop (repeatable)")
    parser.add_argument("--grid", metavar="KEY=V1,V2", action="append", default=[],
                        help="run every combination of these values, each for every seed "
                             "(repeatable)")
    parser.add_argument("--address", default=None,
                        help="Ray cluster to use: 'auto' (the cluster on this machine), "
                             "HOST:PORT (a head's address) or ray://HOST:10001; default: "
                             "start a local Ray of the sweep's own")
    parser.add_argument("--num-cpus", type=int, default=None,
                        help="CPUs of the local Ray (default: all); not with --address")
    parser.add_argument("--cpus-per-run", type=int, default=1,
                        help="CPUs (and TensorFlow/BLAS threads) per run (default 1)")
    parser.add_argument("--max-retries", type=int, default=1,
                        help="retries of a run whose process or worker failed (default 1)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--no-figures", action="store_true",
                        help="do not draw success_rate.png and distance_bands.png")
    parser.add_argument("--log-level", default="INFO", help="logging level (default INFO)")
    return parser


def plan(args: argparse.Namespace, extra: Sequence[str]) -> Tuple[List[RunSpec], List[Dict]]:
    """The runs and settings of parsed ``args`` (ValueError naming a bad argument)."""
    tasks = task_names()
    if args.task not in tasks:
        raise ValueError(f"unknown task {args.task!r}; choose one of {', '.join(tasks)}")
    seeds = parse_seeds(args.seeds)
    if args.cpus_per_run < 1:
        raise ValueError(f"--cpus-per-run must be at least 1, got {args.cpus_per_run}")
    if args.max_retries < 0:
        raise ValueError(f"--max-retries must be at least 0, got {args.max_retries}")
    if args.address is not None:
        split_address(args.address)
        if args.address == "local":
            args.address = None  # the default, said explicitly
    if args.num_cpus is not None and (args.num_cpus < 1 or args.address):
        raise ValueError("--num-cpus must be at least 1 and is for a local Ray only")
    for flag in extra:
        name = flag.split("=", 1)[0].lstrip("-").replace("-", "_")
        if flag.startswith("-") and name in RESERVED:
            raise ValueError(f"{flag} after -- is set by the sweep itself")
    fixed = [parse_assignment(text) for text in args.fixed]
    grid = [parse_assignment(text, grid=True) for text in args.grid]
    parser = task_parser(args.task)
    if parser is None:
        logger.info("the %s task's flags cannot be checked here: a bad flag fails its runs",
                    args.task)
    combos = settings(fixed, grid, parser)
    if parser is not None:
        for label, flags in combos:
            try:
                check_task_flags(parser, [*flags, *extra])
            except ValueError as err:
                raise ValueError(f"setting {label}: {args.task} rejects its flags: {err}") \
                    from None
    output = os.path.abspath(args.output or os.path.join("runs", f"sweep-{args.task}"))
    specs = [RunSpec(args.task, seed, label, tuple([*flags, *extra]),
                     os.path.join(output, label, f"seed-{seed}"))
             for label, flags in combos for seed in seeds]
    described = [{"label": label, "flags": [*flags, *extra]} for label, flags in combos]
    return specs, described


def _configure_logging(level: str) -> None:
    logging.basicConfig(level=logging.WARNING,
                        format="%(asctime)s %(name)s %(levelname)s: %(message)s")
    logging.getLogger("pilco").setLevel(getattr(logging, str(level).upper(), logging.INFO))


def _start_ray(args: argparse.Namespace) -> Tuple[bool, float]:
    """Connect to (or start) Ray; returns ``(started here, seconds)``."""
    import ray

    if ray.is_initialized():
        return False, 0.0
    t0 = time.perf_counter()
    if args.address:
        try:
            ray.init(address=args.address, log_to_driver=False,
                     logging_level=logging.WARNING)
        except Exception as err:  # noqa: BLE001 - Ray raises several kinds; all mean this
            raise SweepError(f"--address {args.address}: Ray could not connect ({err}); "
                             f"start a cluster (`ray start --head`), or leave out "
                             f"--address for a Ray of the sweep's own") from err
    else:
        # local workers and their runs import the same pilco as this process
        import pilco

        root = os.path.dirname(os.path.dirname(os.path.abspath(pilco.__file__)))
        paths = [root, *[p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]]
        os.environ["PYTHONPATH"] = os.pathsep.join(dict.fromkeys(paths))
        # address="local": always a new Ray of this process's own, never a cluster that
        # runs (or ran) on this machine and left its address in Ray's temp folder
        ray.init(address="local", num_cpus=args.num_cpus, include_dashboard=False,
                 log_to_driver=False, logging_level=logging.WARNING)
    seconds = time.perf_counter() - t0
    logger.info("Ray %s in %.1f s: %s CPUs", "connected" if args.address else "started",
                seconds, ray.cluster_resources().get("CPU"))
    return True, seconds


def _on_result(spec: RunSpec, summary: Dict[str, Any]) -> None:
    seconds = (summary.get("seconds") or {}).get("total")
    logger.info("%s: success %s, solved at episode %s, %s s", spec.name,
                aggregate.run_success(summary), summary.get("solved_at_episode"),
                "?" if seconds is None else f"{seconds:.0f}")


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run the sweep; exit status 0 (every run finished), 1 (some failed), 130
    (interrupted: Ctrl-C or SIGTERM), 2 (bad arguments, the output directory in use by
    another sweep, a Ray cluster that does not answer)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    extra: List[str] = []
    if "--" in argv:
        cut = argv.index("--")
        argv, extra = argv[:cut], argv[cut + 1:]
    parser = build_parser()
    args = parser.parse_args(argv)
    args.command = ["python", "-m", "pilco.sweep", *argv, *(["--", *extra] if extra else [])]
    _configure_logging(args.log_level)
    try:
        specs, described = plan(args, extra)
    except ValueError as err:
        parser.error(str(err))
    output = os.path.dirname(os.path.dirname(specs[0].directory))
    try:
        lock = lock_output(output)
    except SweepError as err:
        parser.exit(2, f"{parser.prog}: error: {err}\n")
    try:
        try:
            done = {spec: runs.finished_summary(spec) for spec in specs}
        except ValueError as err:
            parser.error(str(err))
        return _sweep(args, parser, specs, described, extra, output, done)
    finally:
        lock.close()


def _sweep(args: argparse.Namespace, parser: argparse.ArgumentParser,
           specs: Sequence[RunSpec], described: Sequence[Dict], extra: Sequence[str],
           output: str, done: Dict[RunSpec, Optional[Dict[str, Any]]]) -> int:
    """Run the unfinished ``specs`` (the output directory locked), write the report."""
    todo = [spec for spec in specs if done[spec] is None]
    logger.info("%s: %d run(s) in %d setting(s), %d finished already, %d to run", args.task,
                len(specs), len(described), len(specs) - len(todo), len(todo))
    t0 = time.perf_counter()
    ray_seconds, started = None, False
    outcome = runs.SweepOutcome()
    try:
        if todo:
            try:
                check_ray_address(args.address)
                started, ray_seconds = _start_ray(args)
            except KeyboardInterrupt:
                outcome = runs.SweepOutcome(not_run=list(todo), interrupted=True)
            except SweepError as err:
                parser.exit(2, f"{parser.prog}: error: {err}\n")
            else:
                from tqdm.contrib.logging import logging_redirect_tqdm

                with logging_redirect_tqdm():
                    outcome = runs.execute(todo, cpus_per_run=args.cpus_per_run,
                                           max_retries=args.max_retries,
                                           progress=not args.no_progress,
                                           on_result=_on_result)
    finally:
        if started:
            import ray

            with contextlib.suppress(Exception):
                ray.shutdown()
    wall = time.perf_counter() - t0
    report = write_report(args, specs, described, outcome, output, wall, ray_seconds, extra)
    print(aggregate.format_table(report["results"],
                                 title=f"{args.task}: {len(specs)} run(s), wall time "
                                       f"{wall:.0f} s ({output})"))
    for failure in report["failures"]:
        print(f"\nFAILED {failure['setting']}/seed-{failure['seed']}: {failure['error']}")
        if failure.get("stderr_tail"):
            print("  " + failure["stderr_tail"].replace("\n", "\n  "))
    if outcome.interrupted:
        print(f"\nInterrupted: {len(outcome.not_run)} run(s) did not finish; the same "
              f"command continues the sweep.")
        return 130
    return 1 if outcome.failed else 0


def write_report(args: argparse.Namespace, specs: Sequence[RunSpec],
                 described: Sequence[Dict], outcome, output: str, wall: float,
                 ray_seconds: Optional[float], extra: Sequence[str]) -> Dict[str, Any]:
    """Aggregate every finished run on disk, write ``sweep.json`` and the figures."""
    failed = {spec: failure for spec, failure in outcome.failed}
    not_run = set(outcome.not_run)
    now = set(outcome.finished)
    per_setting: Dict[str, List[Dict[str, Any]]] = {d["label"]: [] for d in described}
    run_rows = []
    for spec in specs:
        row = {"setting": spec.label, "seed": spec.seed, "directory": spec.directory}
        summary = None
        if spec in failed:
            row.update(status="failed", error=failed[spec]["error"])
        elif spec in not_run:
            row["status"] = "not_run"
        else:
            summary = runs.finished_summary(spec)
        if summary is not None:
            per_setting[spec.label].append(summary)
            row.update(status="finished" if spec in now else "skipped",
                       success=aggregate.run_success(summary),
                       solved_at_episode=summary.get("solved_at_episode"))
        elif "status" not in row:
            row["status"] = "missing"
        run_rows.append(row)
    results = {}
    for d in described:
        label = d["label"]
        rows = [r for r in run_rows if r["setting"] == label]
        results[label] = aggregate.aggregate_setting(
            per_setting[label], runs=len(rows),
            failed=sum(r["status"] == "failed" for r in rows),
            not_run=sum(r["status"] in ("not_run", "missing") for r in rows))
        for field, what in (("commit", "code versions"), ("onednn", "oneDNN settings"),
                            ("cpu", "CPU models")):
            seen = results[label]["provenance"][field]
            if len(seen) > 1:
                logger.warning("%s: the runs mix %d %s (%s); their rate is not one "
                               "setting's", label, len(seen), what,
                               ", ".join(f"{k}: {v}" for k, v in sorted(seen.items())))
    report = {
        "task": args.task,
        "command": list(getattr(args, "command", [])),
        "seeds": sorted({s.seed for s in specs}),
        "settings": list(described),
        "extra_flags": list(extra),
        "wall_seconds": wall,
        "ray": {"address": args.address or "local", "start_seconds": ray_seconds,
                "cpus_per_run": args.cpus_per_run, "max_retries": args.max_retries},
        "interrupted": bool(outcome.interrupted),
        "results": results,
        "failures": [{"setting": spec.label, "seed": spec.seed, **failure}
                     for spec, failure in outcome.failed],
        "runs": run_rows,
    }
    write_json_atomic(os.path.join(output, "sweep.json"), report)
    if not args.no_figures:
        title = f"{args.task}, seeds {args.seeds}"
        figures.success_rate_figure(per_setting, os.path.join(output, "success_rate.png"),
                                    title=title)
        figures.distance_bands_figure(per_setting, os.path.join(output, "distance_bands.png"),
                                      title=title)
    logger.info("results in %s", os.path.join(output, "sweep.json"))
    return report
