"""PILCO on the paper's 7-DoF Fetch joint-space reacher (paper §4, §5.1).

4 episodes of at most 50 steps (1 random, 3 learned); an RBF policy of 50 basis functions
rotating the 7 joints by at most 0.1 rad a step; 10 dynamics GPs (gripper position and
joint angles); the saturating cost of the gripper's distance to the target. An episode
stops once the gripper is within 5 cm. Every setting is a flag (``--help``); the task
itself, and the settings the paper leaves open, are in :mod:`pilco.tasks.reacher`.

Usage::

    python examples/reacher.py --seed 0
    python examples/reacher.py --resume runs/reacher-seed0 --episodes 6
"""
import sys

from pilco.runtime import quiet_tensorflow

quiet_tensorflow()  # before TensorFlow loads: no C++ start-up lines, no CUDA probes on a CPU

from pilco.tasks.reacher import REACHER as task  # noqa: E402


def main(argv=None) -> int:
    # 1. settings (the paper's defaults; --resume DIR continues a saved run)
    settings = task.parse(argv)
    # 2. the task: Fetch arm, RBF policy, GP dynamics, cost on the gripper position
    exp = task.experiment(settings)
    # 3. PILCO: a random episode, then per episode: train GPs, optimise policy, apply it
    summary = task.run(exp, settings)
    # 4. report: tables, figures, the final episode as a GIF (exit 130 after Ctrl-C)
    return task.finish(exp, summary, settings)


if __name__ == "__main__":
    sys.exit(main())
