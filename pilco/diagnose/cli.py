"""The command line ``python -m pilco.diagnose RUN_DIR [--episode K]``: reopen a run
(:func:`pilco.diagnose.reopen.open_run`), diagnose learned episode K (default the last),
print the report, write it to ``RUN_DIR/diagnosis.json`` (or ``--output``) and log the
verdict.

Candidate policies run on the real system only where the run's environment can be made
from its settings (a task's ``system_from_settings``; not where the system changes
during the run, as the adaptation's arm breaks).
"""
from __future__ import annotations

import argparse
import logging
import os
from typing import Optional, Sequence

from ..runtime import configure_logging, configure_threads, log_level, quiet_tensorflow

__all__ = ["build_parser", "main"]

logger = logging.getLogger(__name__)


def build_parser() -> argparse.ArgumentParser:
    """The flags of ``python -m pilco.diagnose``."""
    parser = argparse.ArgumentParser(
        prog="python -m pilco.diagnose",
        description="Diagnose a learned episode of a PILCO run: model, optimiser or objective.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("run_dir", help="run directory (data.npz, agent.npz, progress.json)")
    parser.add_argument("--episode", type=int, default=None,
                        help="learned episode to diagnose (default: the last)")
    parser.add_argument("--restarts", type=int, default=3,
                        help="policy optimisations from random policies on the episode's model")
    parser.add_argument("--seed", type=int, default=0, help="seed of the restarts")
    parser.add_argument("--no-rollouts", action="store_true",
                        help="do not run the candidate policies on the real system")
    parser.add_argument("--replay", action="store_true",
                        help="replay the run's learning even for the last episode (a check "
                             "that the saved agent is reproduced)")
    parser.add_argument("--output", default=None,
                        help="JSON file to write (default RUN_DIR/diagnosis.json)")
    parser.add_argument("--starts", type=int, default=20,
                        help="run the episode's policy from this many other start states of "
                             "the task and compare its expected return with the start "
                             "mixture's (0: not)")
    parser.add_argument("--threads", type=int, default=0,
                        help="TensorFlow intra- and inter-op threads (0: as a run has them, one "
                             "intra-op thread, so that replayed episodes are the run's own)")
    parser.add_argument("--log-level", default="INFO", type=log_level, help="logging level")
    return parser


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run the command line on ``argv`` (default ``sys.argv[1:]``); returns the exit code."""
    # TensorFlow's C++ log lines drown the report; pilco logs through `logging`.
    quiet_tensorflow()
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.threads < 0:
        parser.error(f"--threads must be 0 or more, got {args.threads}")
    if args.starts < 0:
        parser.error(f"--starts must be 0 or more, got {args.starts}")
    configure_logging(args.log_level)
    # 0: the threads of a run (one intra-op thread, BLAS on one), so that a replayed
    # episode is the run's own
    configure_threads(args.threads or None)
    from .diagnosis import diagnose, write_diagnosis
    from .reopen import open_run
    from .report import format_report

    from ..tasks import TASKS, get_task

    exp = open_run(args.run_dir)
    rollouts = not args.no_rollouts
    task = exp.config.task
    if rollouts and task in TASKS and not get_task(task).system_from_settings:
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
