"""PILCO on any gymnasium environment with Box observations and actions.

The environment is named on the command line, with the target state and the cost widths
of the saturating cost; each action can be held for several steps, and the success rule is
stated as a setting: the last episode survived ``--success-steps`` steps (an environment
that terminates when it fails), held the target for them, reached it, or advanced a
distance (locomotion, whose reward is a linear term minus penalties near joint limits).
``--preset`` gives other libraries' examples on gymnasium's current versions
(``inverted-pendulum``, ``torchrl``, ``inverted-double-pendulum``, ``mountain-car``,
``pendulum``, ``swimmer``).
Every setting is a flag (``--help``); the task itself is :mod:`pilco.tasks.gym`.

Usage::

    python examples/gym.py --env InvertedPendulum-v5 --horizon 40 --episodes 6
    python examples/gym.py --preset torchrl --seed 0
    python examples/gym.py --preset mountain-car --seed 0
    python examples/gym.py --env Pendulum-v1 --target 1 0 0 --widths 0.5 0.5 inf \\
        --action-repeat 3 --success hold --success-steps 10 --success-distance 0.4
    python examples/gym.py --env Swimmer-v5 --widths inf --linear 0 0 0 1 0 0 0 0 \
        --action-repeat 5 --success advance --success-distance 1
"""
import sys

from pilco.runtime import quiet_tensorflow

quiet_tensorflow()  # before TensorFlow loads: no C++ start-up lines, no CUDA probes on a CPU

from pilco.tasks.gym import GYM as task  # noqa: E402


def main(argv=None) -> int:
    # 1. settings: the environment, its target and cost widths, the success rule
    settings = task.parse(argv)
    # 2. the task: the environment (checked before any episode), RBF policy, GP dynamics
    exp = task.experiment(settings)
    # 3. PILCO: random episodes, then per episode: train GPs, optimise policy, apply it
    summary = task.run(exp, settings)
    # 4. report: tables and figures (exit 130 after Ctrl-C)
    return task.finish(exp, summary, settings)


if __name__ == "__main__":
    sys.exit(main())
