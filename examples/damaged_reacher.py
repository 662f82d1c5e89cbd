"""PILCO on the damaged 7-DoF Fetch reacher (paper §5.2).

The reacher of ``examples/reacher.py`` with its elbow (``elbow_flex``) motor unresponsive,
as in the paper: the joint ignores every command and stays at its start angle
(``--damage-mode stuck``, default); the policy is not told. ``--damage-mode straight``
forces the elbow to 0 rad instead, a harder variant whose arm starts ~1.2 m from the
target (give it a wider cost, e.g. ``--cost-width 0.4``). ``--preset paper-code`` runs
the published damaged-arm script's settings. Every setting is a flag (``--help``); the
task is :mod:`pilco.tasks.reacher` (``damaged=True``).

Usage::

    python examples/damaged_reacher.py --seed 0
"""
import sys

from pilco.runtime import quiet_tensorflow

quiet_tensorflow()  # before TensorFlow loads: no C++ start-up lines, no CUDA probes on a CPU

from pilco.tasks.reacher import DAMAGED_REACHER as task  # noqa: E402


def main(argv=None) -> int:
    # 1. settings (the paper's defaults, the damage; --resume DIR continues a saved run)
    settings = task.parse(argv)
    # 2. the task: the damaged Fetch arm, RBF policy, GP dynamics, cost on the gripper
    exp = task.experiment(settings)
    # 3. PILCO: a random episode, then per episode: train GPs, optimise policy, apply it
    summary = task.run(exp, settings)
    # 4. report: tables, figures, the final episode as a GIF (exit 130 after Ctrl-C)
    return task.finish(exp, summary, settings)


if __name__ == "__main__":
    sys.exit(main())
