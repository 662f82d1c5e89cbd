"""PILCO on the damaged 7-DoF Fetch reacher (paper §5.2).

The same task and settings as ``examples/reacher.py`` on ``pilco/FetchJointReacherDamaged-v0``:
the elbow (``elbow_flex``) ignores every command and, as in the paper's code, is forced to
0 rad (``--damage-mode zero``, default) or stays where it was (``--damage-mode stuck``). The
policy is not told. Unlike the healthy reacher the default cost width is
``--cost-width 0.4``: the straightened arm starts ~1.1 m from the target, where the
healthy default (0.2 m) is flat and the policy never moves. See ``python examples/damaged_reacher.py --help`` for every setting.

Usage::

    python examples/damaged_reacher.py --seed 0
"""
from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from reacher import main  # noqa: E402 - the shared reacher script

if __name__ == "__main__":
    sys.exit(main(damaged=True))
