"""Safe PILCO: two cars at a crossing, the first must pass it without a collision.

The first car's acceleration is the action; a learned policy runs only when its predicted
probability of a collision over the horizon is below ``--risk-threshold``; otherwise the
risk's weight ``--mu`` grows and the policy is searched again, and an episode with no safe
policy brakes (``--safe-action``). Every setting is a flag (``--help``); the task itself
is :mod:`pilco.tasks.cars`, the loop :mod:`pilco.experiment.safety`.

Usage::

    python examples/cars.py --seed 0
    python examples/cars.py --seed 0 --risk-threshold 0.05 --episodes 12
"""
import sys

from pilco.runtime import quiet_tensorflow

quiet_tensorflow()  # before TensorFlow loads: no C++ start-up lines, no CUDA probes on a CPU

from pilco.tasks.cars import CARS as task  # noqa: E402


def main(argv=None) -> int:
    # 1. settings: the risk threshold, the risk's weight mu, the safe action
    settings = task.parse(argv)
    # 2. the task: the cars, an RBF policy, the reward x1 minus mu times the collision risk
    exp = task.experiment(settings)
    # 3. Safe PILCO: random episodes, then per episode: train GPs, search a policy until
    #    its predicted risk is below the threshold, run it (or brake if none is)
    summary = task.run(exp, settings)
    # 4. report: tables, safety counts and figures (exit 130 after Ctrl-C)
    return task.finish(exp, summary, settings)


if __name__ == "__main__":
    sys.exit(main())
