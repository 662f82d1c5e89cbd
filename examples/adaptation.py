"""Adaptation to damage: learn to reach on the healthy Fetch arm, then break its elbow
mid-run and keep learning with the same agent (the paper's motivation, §5.2).

The healthy arm learns as ``examples/reacher.py`` does (a random episode, then up to 3
learned episodes, stopping at the first that reaches), then the damage (the elbow stuck
at its angle; ``--damage-mode straight`` straightens it; the agent is not told), then up
to 4 learned damaged episodes (until the arm reaches again). In the first damaged episode
the agent watches its joints: after 3 steps the elbow has not followed its commands, so
the episode pauses, the agent stops commanding it, its model sees that joint's commands
as 0 (the healthy episodes then describe the damaged arm as well), and the policy is
searched again from where the arm is; the episode goes on with it
(``--no-replan-stuck-joints``: only after the episode). Every reacher setting is a flag
too (``--help``); the task is :mod:`pilco.tasks.adaptation`. Figure
``adaptation_distance.png``: the distance per step, healthy and damaged episodes.

Usage::

    python examples/adaptation.py --seed 0
"""
import sys

from pilco.runtime import quiet_tensorflow

quiet_tensorflow()  # before TensorFlow loads: no C++ start-up lines, no CUDA probes on a CPU

from pilco.tasks.adaptation import ADAPTATION  # noqa: E402

if __name__ == "__main__":
    # the four steps of examples/reacher.py (parse, experiment, run, finish) in one call:
    # PILCO on the healthy arm until it reaches, the damage, PILCO until it reaches again
    sys.exit(ADAPTATION.main())
