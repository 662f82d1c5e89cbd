"""``python -m pilco.diagnose RUN_DIR [--episode K]``: why did a run fail?

Reopens a run directory written by a task (``python -m pilco.tasks``, the examples, the
seed sweep), diagnoses learned episode K (default the last) with
:func:`pilco.experiment.diagnose.diagnose` (the checks and the verdict rules are in that
module's docstring), prints the report, writes it to ``RUN_DIR/diagnosis.json`` and logs
the verdict. Runs of the tasks ``reacher``, ``damaged_reacher``, ``cartpole``,
``pendulum`` and ``adaptation`` are reopened through their task (its agent builder
replays the learning of an earlier episode; the adaptation's replay redoes the damage's
changes to the agent, :func:`pilco.tasks.adaptation.replay_damage`); other runs through
their saved agent, which is enough for the last episode. Candidate policies run on the
real system only where the run's environment can be made from its settings (not for the
adaptation, whose arm breaks during the run).
"""
from __future__ import annotations

import argparse
import importlib
import logging
import os
import sys
from typing import Optional, Sequence

from pilco.runtime import configure_logging, configure_threads, log_level, quiet_tensorflow

__all__ = ["open_run", "build_parser", "main"]

logger = logging.getLogger(__name__)

#: tasks whose runs can be reopened with their agent builder
REOPENABLE = ("reacher", "damaged_reacher", "cartpole", "pendulum", "adaptation")


def open_run(directory: str):
    """The run saved in ``directory`` as a resumed :class:`~pilco.experiment.Experiment`
    (its episodes, records and settings; the agent builder when the task is known)."""
    from .experiment import Experiment, ExperimentConfig, RunStore

    progress = RunStore(directory).load_progress()
    task = progress["config"]["task"]
    argv = ["--resume", directory, "--quiet", "--no-render"]
    level = logging.getLogger().level
    try:
        if task in ("reacher", "damaged_reacher"):
            from .tasks import reacher

            damaged = task == "damaged_reacher"
            return reacher.make_experiment(reacher.parse_args(argv, damaged), task, damaged)
        if task in REOPENABLE:
            module = importlib.import_module(f"{__package__}.tasks.{task}")
            return module.make_experiment(module.parse_args(argv))
    finally:
        logging.getLogger().setLevel(level)  # the task's parser sets the run's log level
    logger.info("task %r is not reopened through its task: the saved agent is used", task)
    return Experiment.resume(directory, ExperimentConfig(**progress["config"]),
                             build_agent=None)


def build_parser() -> argparse.ArgumentParser:
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
    parser.add_argument("--threads", type=int, default=0,
                        help="TensorFlow intra- and inter-op threads (0: TensorFlow's default)")
    parser.add_argument("--log-level", default="INFO", type=log_level, help="logging level")
    return parser


def main(argv: Optional[Sequence[str]] = None) -> int:
    # TensorFlow's C++ log lines drown the report; pilco logs through `logging`.
    quiet_tensorflow()
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.threads < 0:
        parser.error(f"--threads must be 0 or more, got {args.threads}")
    configure_logging(args.log_level)
    if args.threads:
        configure_threads(args.threads)
    from .experiment.diagnose import diagnose, write_diagnosis
    from .experiment.report import format_diagnosis

    exp = open_run(args.run_dir)
    rollouts = not args.no_rollouts
    if rollouts and exp.config.task == "adaptation":
        logger.warning("the adaptation task breaks the arm during the run: the candidate "
                       "policies are not run on the real system")
        rollouts = False
    try:
        result = diagnose(exp, args.episode, restarts=args.restarts, seed=args.seed,
                          rollouts=rollouts, replay=args.replay)
    finally:
        exp.close()
    path = write_diagnosis(result, args.output or os.path.join(args.run_dir, "diagnosis.json"))
    print(format_diagnosis(result))
    print(f"\nWritten: {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
