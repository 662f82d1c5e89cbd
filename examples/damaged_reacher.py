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

from pilco.tasks.reacher import DAMAGED_REACHER  # noqa: E402

if __name__ == "__main__":
    # the four steps of examples/reacher.py (parse, experiment, run, finish) in one call:
    # the damaged Fetch arm, RBF policy, GP dynamics, cost on the gripper
    sys.exit(DAMAGED_REACHER.main())
