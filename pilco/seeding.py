"""Random generators of the library's random draws (initial policies, restarts).

A ``seed`` makes a draw repeatable. Without one (``seed=None``) the generator's seed is
drawn from NumPy's global random state, so ``np.random.seed(s)`` at the top of a script,
as the paper's scripts start, makes every unseeded draw of pilco repeatable as well; a
process that never seeds NumPy still gets different draws each run.
"""
from __future__ import annotations

from typing import Optional

import numpy as np

__all__ = ["generator"]


def generator(seed: Optional[int] = None) -> np.random.Generator:
    """``np.random.default_rng(seed)``; for ``seed=None`` the seed comes from
    ``np.random`` (the global state ``np.random.seed`` sets)."""
    if seed is None:
        seed = int(np.random.randint(0, 2 ** 31 - 1))
    return np.random.default_rng(seed)
