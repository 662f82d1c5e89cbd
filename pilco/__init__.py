"""pilco: Probabilistic Inference for Learning COntrol on GPflow.

Sub-modules:

- :mod:`pilco.models`: ``MGPR``, ``SMGPR`` (GP dynamics with moment matching) and ``PILCO``.
- :mod:`pilco.protocols`: what ``PILCO`` calls on a controller and a reward (to write your own).
- :mod:`pilco.controllers`: squashing functions and linear / RBF policies.
- :mod:`pilco.rewards`: saturating (exponential), linear, combined and cart-pole rewards.
- :mod:`pilco.angles`: sin/cos augmentation of angle dimensions under a Gaussian
  (:mod:`pilco.features`: the same features of known states, with NumPy).
- saving: ``agent.save(path)`` and ``PILCO.load(path)`` (an agent, to continue learning),
  ``agent.export_policy(path)`` (the policy alone, for :mod:`pilco.deploy`); the file
  layout is :mod:`pilco.models.storage`.
- :mod:`pilco.envs`: gymnasium environments of the paper (cart-pole, Fetch joint reacher).
- :mod:`pilco.deploy`: NumPy-only policy evaluation for robots (no TensorFlow import).
- :mod:`pilco.portable`: the same arithmetic on every x86-64 CPU with AVX2 (set up when
  :mod:`pilco` is imported before numpy).
"""
import logging

from .portable import use_portable_arithmetic

# before anything loads numpy: its loops and OpenBLAS's kernels as every x86-64 CPU with
# AVX2 runs them, so that a seed gives the same run on every such CPU (pilco.portable)
use_portable_arithmetic()

__version__ = "0.1.0"

logging.getLogger(__name__).addHandler(logging.NullHandler())
