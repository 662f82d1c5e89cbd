"""Multi-task PILCO on the Fetch reacher: one policy that reaches any target in a cube.

The reacher of ``examples/reacher.py`` with the target in the state (three context
dimensions the policy reads and the dynamics GPs never predict). Four training targets
drawn within ±15 cm of the paper's target, one episode each in turn (12 episodes: three
rounds, the first episode random); the policy maximises the sum of the four targets'
expected returns. Then the final policy runs on 20 held-out targets it never trained on;
``targets.png`` shows which it reached and in how many steps. Every setting is a flag
(``--help``); the task is :mod:`pilco.tasks.reacher_multi`.

Usage::

    python examples/reacher_multi.py --seed 0
    python examples/reacher_multi.py --training-targets 6 --episodes 13 --target-cube 0.1
"""
import sys

from pilco.runtime import quiet_tensorflow

quiet_tensorflow()  # before TensorFlow loads: no C++ start-up lines, no CUDA probes on a CPU

from pilco.tasks.reacher_multi import REACHER_MULTI  # noqa: E402

if __name__ == "__main__":
    # the four steps of examples/reacher.py (parse, experiment, run, finish) in one call,
    # the run ending with the test on the held-out targets
    sys.exit(REACHER_MULTI.main())
