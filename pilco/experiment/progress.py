"""Progress bars of a run (tqdm on stderr) and the optimisers' per-iteration callback."""
from __future__ import annotations

import sys
from typing import Callable, Optional

from .signals import raise_if_stop_requested

__all__ = ["progress_bar", "optimizer_callback"]


def progress_bar(total: Optional[int], desc: str, quiet: bool, unit: str = "it"):
    """A tqdm bar on stderr that disappears when closed (disabled when ``quiet``)."""
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, unit=unit, disable=quiet, leave=False,
                dynamic_ncols=True, file=sys.stderr)


def optimizer_callback(bar) -> Callable[[int], None]:
    """``callback(iteration)`` for ``optimize_policy``/``optimize_models``: ticks ``bar``
    and stops the optimiser (``KeyboardInterrupt``) once SIGTERM arrived."""

    def callback(iteration: int) -> None:  # one tick per iteration
        bar.update(1)
        raise_if_stop_requested()

    return callback
