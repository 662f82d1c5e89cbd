"""Adaptation to damage: learn to reach on the healthy Fetch arm, then break its elbow
mid-run and keep learning with the same agent (the paper's motivation, §5.2).

A random episode and up to 4 learned healthy episodes (until one reaches), then the
damage (the elbow stuck at its angle; ``--damage-mode straight`` straightens it), then up to
4 learned damaged episodes (until the arm reaches again). The first damaged episode
shows which joint stopped following its commands; from the next one on the agent stops
commanding it and its model sees that joint's commands as 0, so the healthy episodes
describe the damaged arm as well and count as equals (``--no-stop-stuck-joints``: they
keep 100 times the damaged ones' noise variance instead, ``--old-data-noise``;
``--drop-old-data`` forgets them). Every reacher setting is a flag too (``--help``); the
task is :mod:`pilco.tasks.adaptation`. Figure ``adaptation_distance.png``: the distance
per step, healthy and damaged episodes.

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
