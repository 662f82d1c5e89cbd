"""The command line ``pilco diagnose RUN_DIR [--episode K]`` (also ``python -m
pilco.diagnose``): reopen a run (:func:`pilco.tasks.open_run`), diagnose learned
episode K (default the last), print the report, write it to ``RUN_DIR/diagnosis.json``
(or ``--output``) and log the verdict. A missing or wrong run directory, or an episode
the run did not learn, is a usage error said in one line (status 2).

Candidate policies run on the real system only where the run's environment can be made
from its settings (a task's ``system_from_settings``; not where the system changes
during the run, as the adaptation's arm breaks).
"""
from __future__ import annotations

import argparse
import logging
import os
import sys
from typing import Optional, Sequence, Tuple

from ..runtime import configure_logging, configure_threads, log_level, quiet_tensorflow

__all__ = ["PROG", "EXAMPLES", "build_parser", "check_run_dir", "parse", "main"]

logger = logging.getLogger(__name__)


#: the command's name in its usage line and errors (``python -m pilco.diagnose`` is the same)
PROG = "pilco diagnose"

#: the examples of ``--help`` (each runs: tests/test_command.py)
EXAMPLES = ("runs/reacher-seed5", "runs/reacher-seed5 --episode 3",
            "runs/reacher-seed5 --threads 1 --restarts 3 --output d.json",
            "runs/adaptation-seed8 --episode 6")


def build_parser(prog: str = PROG) -> argparse.ArgumentParser:
    """The flags of ``pilco diagnose``."""
    parser = argparse.ArgumentParser(
        prog=prog,
        description="Diagnose a learned episode of a PILCO run: model, optimiser or objective.",
        epilog="examples:\n" + "\n".join(f"  %(prog)s {e}" for e in EXAMPLES),
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run_dir", metavar="RUN_DIR",
                        help="run directory (data.npz, agent.npz, progress.json)")
    parser.add_argument("--episode", type=int, default=None, metavar="K",
                        help="learned episode to diagnose (default the last)")
    parser.add_argument("--restarts", type=int, default=3,
                        help="policy optimisations from random policies on the episode's "
                             "model (default 3)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the restarts (default 0)")
    parser.add_argument("--no-rollouts", action="store_true",
                        help="do not run the candidate policies on the real system")
    parser.add_argument("--replay", action="store_true",
                        help="replay the run's learning even for the last episode (a check "
                             "that the saved agent is reproduced)")
    parser.add_argument("--output", default=None, metavar="FILE",
                        help="JSON file to write (default RUN_DIR/diagnosis.json)")
    parser.add_argument("--starts", type=int, default=20,
                        help="run the episode's policy from this many other start states of "
                             "the task and compare its expected return with the start "
                             "mixture's (0: not; default 20)")
    parser.add_argument("--threads", type=int, default=0,
                        help="TensorFlow intra- and inter-op threads (0: as a run has them, "
                             "one intra-op thread, so that replayed episodes are the run's "
                             "own; default 0)")
    parser.add_argument("--log-level", default="INFO", type=log_level,
                        help="logging level (default INFO)")
    return parser


def _fail(prog: str, message: str) -> int:
    """A usage error in one line on stderr (no usage text, no traceback): status 2."""
    sys.stderr.write(f"{prog}: error: {message}\n")
    return 2


def check_run_dir(run_dir: str) -> Optional[str]:
    """What is wrong with ``run_dir`` as a run directory, or None: it must be a directory
    holding ``progress.json``."""
    if not os.path.exists(run_dir):
        return f"{run_dir}: no such run directory"
    if not os.path.isdir(run_dir):
        return f"{run_dir}: not a directory"
    if not os.path.isfile(os.path.join(run_dir, "progress.json")):
        return f"{run_dir}: not a run directory (no progress.json)"
    return None


def parse(argv: Optional[Sequence[str]] = None,
          prog: str = PROG) -> Tuple[argparse.ArgumentParser, argparse.Namespace]:
    """The parser and the checked arguments of ``argv`` (argparse's usage error, status 2,
    on a bad flag or value; the run directory is checked by :func:`main`)."""
    parser = build_parser(prog)
    args = parser.parse_args(argv)
    if args.threads < 0:
        parser.error(f"--threads must be 0 or more, got {args.threads}")
    if args.starts < 0:
        parser.error(f"--starts must be 0 or more, got {args.starts}")
    if args.restarts < 0:
        parser.error(f"--restarts must be 0 or more, got {args.restarts}")
    return parser, args


def main(argv: Optional[Sequence[str]] = None, prog: str = PROG) -> int:
    """Run the command line on ``argv`` (default ``sys.argv[1:]``); returns the exit code:
    0, or 2 after a usage error (a bad flag, a missing or wrong run directory, an episode
    the run did not learn), said in one line."""
    # TensorFlow's C++ log lines drown the report; pilco logs through `logging`.
    quiet_tensorflow()
    parser, args = parse(argv, prog)
    problem = check_run_dir(args.run_dir)
    if problem:
        return _fail(parser.prog, problem)
    configure_logging(args.log_level)
    # 0: the threads of a run (one intra-op thread, BLAS on one), so that a replayed
    # episode is the run's own
    configure_threads(args.threads or None)
    from .diagnosis import diagnose, write_diagnosis
    from .report import format_report

    from ..tasks import get_task, open_run
    from ..tasks.base import RunDirectoryError

    try:
        exp = open_run(args.run_dir)
    except (OSError, ValueError, KeyError) as err:
        # a damaged or foreign directory: its files are missing, unreadable or not a run's
        cause = err.__cause__ if isinstance(err, RunDirectoryError) and err.__cause__ else err
        return _fail(parser.prog, f"{args.run_dir}: cannot reopen the run "
                                  f"({type(cause).__name__}: {cause})")
    learned = [i for i, record in enumerate(exp.records, start=1) if not record["random"]]
    if args.episode is not None and args.episode not in learned or not learned:
        exp.close()
        which = "no learned episode" if args.episode is None else \
            f"episode {args.episode} is not a learned episode"
        return _fail(parser.prog, f"{args.run_dir}: {which} (learned episodes: "
                                  f"{', '.join(map(str, learned)) or 'none'})")
    rollouts = not args.no_rollouts
    task = exp.config.task
    try:
        changes_system = not get_task(task).system_from_settings
    except (ValueError, TypeError):  # reopened from its saved agent (pilco.tasks.open_run)
        changes_system = False
    if rollouts and changes_system:
        logger.warning("the %s task changes its system during the run: the candidate "
                       "policies are not run on the real system", task)
        rollouts = False
    try:
        result = diagnose(exp, args.episode, restarts=args.restarts, seed=args.seed,
                          rollouts=rollouts, replay=args.replay, starts=args.starts)
    finally:
        exp.close()
    path = write_diagnosis(result, args.output or os.path.join(args.run_dir, "diagnosis.json"))
    print(format_report(result))
    print(f"\nWritten: {path}")
    return 0
