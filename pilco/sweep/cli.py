"""``python -m pilco.sweep TASK --seeds 0-19 ...``: many seeds (and settings) of a task on
Ray, then success rates, quartiles and figures.

Every argument is checked before Ray starts: the task name, the seed list, the ``--set``
and ``--grid`` assignments, the form of ``--address`` and every flag a run will get,
with the task's own parser (:func:`pilco.tasks.build_parser`), so a typo fails in a
second, not in twenty processes (:mod:`pilco.sweep.flags`).

Without ``--address`` the sweep starts a Ray of its own, whatever Ray runs (or ran) on
the machine. A cluster named by ``--address`` must accept a connection within
:data:`~pilco.sweep.preflight.CONNECT_TIMEOUT` seconds, or the sweep stops with a
message naming it. The sweep holds an exclusive lock on ``DIR/sweep.lock`` while it
runs: a second sweep into the same directory stops at once instead of writing alongside
it (the kernel releases the lock when the holder exits, even when it is killed;
:mod:`pilco.sweep.preflight`).
"""
from __future__ import annotations

import argparse
import contextlib
import logging
import os
import sys
import time
from typing import Any, Dict, List, Optional, Sequence, Tuple

import pilco.tasks
from pilco.runtime import configure_logging, log_level

from . import aggregate, runs
from .flags import RESERVED, parse_assignment, parse_seeds, settings
from .preflight import SweepError, check_ray_address, lock_output, split_address
from .report import write_report
from .runs import RunSpec

__all__ = ["PROG", "EXAMPLES", "build_parser", "plan", "main"]

logger = logging.getLogger("pilco.sweep")

#: the command's name in its usage and error messages (``python -m pilco.sweep`` is the same)
PROG = "pilco sweep"

#: the examples of ``--help`` (each runs: tests/test_command.py)
EXAMPLES = ("cartpole --seeds 0-19",
            "reacher --seeds 0-9 --grid cost_width=0.2,0.3",
            "pendulum --seeds 0-9",
            "cartpole --seeds 0,3,5-7 --set policy_early_stop=solved -- --episodes 10",
            "damaged_reacher --seeds 0-99 --address auto --cpus-per-run 2")


def build_parser(prog: str = PROG) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=prog,
        usage="%(prog)s TASK [--seeds SEEDS] [options] [-- TASK FLAGS...]",
        description="Run a PILCO task for many seeds (and settings) on Ray; report success\n"
                    "rates with 95 % Wilson intervals, episodes to solve, distances, times.\n"
                    "Each run is `pilco run TASK --seed S --output DIR/SETTING/seed-S\n"
                    "--quiet --no-render --no-figures [setting flags] [TASK FLAGS]`.\n"
                    "The same command again skips the runs that finished.",
        epilog="examples:\n" + "\n".join(f"  %(prog)s {e}" for e in EXAMPLES),
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("task", metavar="TASK",
                        help=f"one of: {', '.join(pilco.tasks.TASKS)}, or "
                             f"package.module:ATTRIBUTE (a task of your own)")
    parser.add_argument("--seeds", default="0-9",
                        help="seeds: a range 0-19, a list 0,3,5 or both (default 0-9)")
    parser.add_argument("--output", metavar="DIR", default=None,
                        help="sweep directory (default runs/sweep-TASK): runs go to "
                             "DIR/SETTING/seed-S, the aggregate to DIR/sweep.json")
    parser.add_argument("--set", dest="fixed", metavar="KEY=VALUE", action="append",
                        default=[], help="a task flag for every run: horizon=30 is "
                                         "--horizon 30, retrain_unchanged_model=true "
                                         "is --retrain-unchanged-model (repeatable)")
    parser.add_argument("--grid", metavar="KEY=V1,V2", action="append", default=[],
                        help="run every combination of these values, each for every seed "
                             "(repeatable)")
    parser.add_argument("--address", default=None,
                        help="Ray cluster to use: 'auto' (the cluster on this machine), "
                             "HOST:PORT (a head's address) or ray://HOST:10001; default: "
                             "start a local Ray of the sweep's own")
    parser.add_argument("--num-cpus", type=int, default=None,
                        help="CPUs of the local Ray (default all); not with --address")
    parser.add_argument("--cpus-per-run", type=int, default=1,
                        help="CPUs (and TensorFlow/BLAS threads) per run (default 1)")
    parser.add_argument("--max-retries", type=int, default=1,
                        help="retries of a run whose process or worker failed (default 1)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--no-figures", action="store_true",
                        help="do not draw success_rate.png and distance_bands.png")
    parser.add_argument("--log-level", default="INFO", type=log_level,
                        help="logging level of pilco's messages (default INFO)")
    return parser


def plan(args: argparse.Namespace, extra: Sequence[str]) -> Tuple[List[RunSpec], List[Dict]]:
    """The runs and settings of parsed ``args`` (ValueError naming a bad argument)."""
    task = pilco.tasks.get_task(args.task)  # ValueError naming the tasks if unknown
    parser = task.parser()
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
    combos = settings(fixed, grid, parser)
    for label, flags in combos:
        try:  # as a run reads them: flags, then the settings' own checks (one seed's)
            task.read_settings(["--seed", str(seeds[0]), "--output", "x", "--quiet",
                                "--no-render", "--no-figures", *flags, *extra])
        except ValueError as err:
            raise ValueError(f"setting {label}: {args.task} rejects its flags: {err}") \
                from None
    output = os.path.abspath(args.output or os.path.join(
        "runs", f"sweep-{args.task.replace(':', '-')}"))
    root = pilco.tasks.task_import_root(args.task)
    specs = [RunSpec(args.task, seed, label, tuple([*flags, *extra]),
                     os.path.join(output, label, f"seed-{seed}"), import_root=root)
             for label, flags in combos for seed in seeds]
    described = [{"label": label, "flags": [*flags, *extra]} for label, flags in combos]
    return specs, described


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
        except Exception as err:  # Ray raises several kinds; all mean this
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


def main(argv: Optional[Sequence[str]] = None, prog: str = PROG) -> int:
    """Run the sweep; exit status 0 (every run finished), 1 (some failed), 130
    (interrupted: Ctrl-C or SIGTERM), 2 (bad arguments, the output directory in use by
    another sweep, a Ray cluster that does not answer). ``prog`` names the command in
    its messages."""
    argv = list(sys.argv[1:] if argv is None else argv)
    extra: List[str] = []
    if "--" in argv:
        cut = argv.index("--")
        argv, extra = argv[:cut], argv[cut + 1:]
    parser = build_parser(prog)
    args = parser.parse_args(argv)
    args.command = ["python", "-m", "pilco.sweep", *argv, *(["--", *extra] if extra else [])]
    configure_logging(args.log_level, logger="pilco")  # Ray's and others' INFO stay out
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
