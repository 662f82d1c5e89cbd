"""The numbers the diagnosis judges by: when a prediction covers a real value, when the
model is wrong one step ahead, when a re-optimised policy is clearly better, when the cost
is flat. The checks (:mod:`pilco.diagnose.checks`) and the verdict rules
(:mod:`pilco.diagnose.rules`) read them from one :class:`Thresholds`."""
from __future__ import annotations

import dataclasses

__all__ = ["Thresholds"]


@dataclasses.dataclass(frozen=True)
class Thresholds:
    """The numbers of the verdict rules (see :mod:`pilco.diagnose.rules`)."""

    #: a real value is "within the prediction" if within this many predicted std
    z: float = 2.0
    #: the model is wrong one step ahead if fewer one-step errors than this fraction are
    #: within ``z`` std (0.95 for a calibrated Gaussian) ...
    coverage: float = 0.90
    #: ... or fewer than this fraction in some state dimension (one mispredicted dimension,
    #: e.g. a joint held at its limit, is diluted in the overall fraction)
    coverage_dim: float = 0.70
    #: a candidate is clearly better if it lowers the predicted cost by at least
    #: ``max(gain_abs, gain_rel * run's predicted cost)``
    gain_abs: float = 1.0
    gain_rel: float = 0.10
    #: the cost is flat at start distances beyond this many cost widths ...
    flat_widths: float = 3.0
    #: ... and the search stayed on its plateau if the run's predicted cost is at least
    #: this fraction of the horizon's largest cost
    plateau: float = 0.9

    def gain_needed(self, run_cost: float) -> float:
        """The predicted-cost decrease that counts as clearly better than ``run_cost``
        (also the clear margin of a real cost above its prediction)."""
        return max(self.gain_abs, self.gain_rel * abs(float(run_cost)))

    def one_step_wrong(self, coverage: float, worst_dim_coverage: float) -> bool:
        """Whether one-step coverages say the model is wrong along the real episode."""
        return coverage < self.coverage or worst_dim_coverage < self.coverage_dim
