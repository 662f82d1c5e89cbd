"""PILCO on the MATLAB release's cart-pole swing-up (paper §5.3).

8 episodes (1 with random forces, 7 learned) of 40 steps of 0.1 s; the release's
settings: an RBF policy of 10 basis functions drawn from the start distribution, the
saturating cost of the pendulum tip's distance to upright (width 0.25 m), BFGS for the
policy, L-BFGS-B for the GPs, both stopping once they stall; a run not solved by episode 5
adds a search from a random policy per episode until solved. Solved: the tip stays within
0.1 m of the target for the last 10 steps of an episode. Every setting is a flag
(``--help``); the task itself is :mod:`pilco.tasks.cartpole`.

Usage::

    python examples/cartpole.py --seed 0
    python examples/cartpole.py --resume runs/cartpole-seed0 --episodes 12
"""
import sys

from pilco.runtime import quiet_tensorflow

quiet_tensorflow()  # before TensorFlow loads: no C++ start-up lines, no CUDA probes on a CPU

from pilco.tasks.cartpole import CARTPOLE as task  # noqa: E402


def main(argv=None) -> int:
    # 1. settings (the release's defaults; --resume DIR continues a saved run)
    settings = task.parse(argv)
    # 2. the task: cart-pole env, RBF policy, GP dynamics, saturating cost, run directory
    exp = task.experiment(settings)
    # 3. PILCO: a random episode, then per episode: train GPs, optimise policy, apply it
    summary = task.run(exp, settings)
    # 4. report: tables, figures, the final episode as a GIF (exit 130 after Ctrl-C)
    return task.finish(exp, summary, settings)


if __name__ == "__main__":
    sys.exit(main())
