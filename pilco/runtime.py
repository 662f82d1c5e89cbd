"""Process start-up of the command-line tools: logging and TensorFlow's threads."""
from __future__ import annotations

import logging
import os

__all__ = ["configure_logging", "configure_threads"]


def configure_logging(level: str) -> None:
    """Basic logging to stderr at ``level`` (a name such as ``"info"``)."""
    logging.basicConfig(level=getattr(logging, str(level).upper(), logging.WARNING),
                        format="%(asctime)s %(name)s %(levelname)s: %(message)s")


def configure_threads() -> None:
    """One TensorFlow intra-op thread unless ``TF_NUM_INTRAOP_THREADS`` says otherwise (the
    inter-op pool keeps its default, every CPU): the policy objective's groups of output
    pairs (:func:`pilco.moments.pair_groups`) then run side by side, one per CPU, which
    keeps the CPUs busier than TensorFlow's default of splitting each of these small
    batched operations over them (timings: docs/performance.md). Takes effect in a
    process that has not run a TensorFlow operation yet, as a task's does."""
    os.environ.setdefault("TF_NUM_INTRAOP_THREADS", "1")
