"""The API the paper's code (the nrontsis/PILCO GPflow port) shares with this library:
a script written against it runs here unchanged and means the same.

Each test takes one line of such a script (as ``examples/pendulum.py`` writes it) and
checks what it does here, with tiny sizes: 2 basis functions, horizon 3, 2 optimiser
iterations.
"""
from __future__ import annotations

import gpflow
import numpy as np
import pytest
from gpflow import set_trainable

from pilco.controllers import RbfController
from pilco.models import PILCO
from pilco.rewards import ExponentialReward

M_INIT = np.reshape([-1.0, 0.0, 0.0], (1, 3))
S_INIT = np.diag([0.01, 0.05, 0.01])
TARGET = np.array([1.0, 0.0, 0.0])
W = np.diag([2.0, 2.0, 0.3])


def transitions(n=20, seed=0):
    """``X [n, 4] = [cos, sin, dtheta, u]`` and ``Y [n, 3]`` (float32, as gymnasium's
    observations are) of a smooth made-up system."""
    rng = np.random.default_rng(seed)
    theta = rng.uniform(-np.pi, np.pi, n)
    X = np.column_stack([np.cos(theta), np.sin(theta), rng.uniform(-2, 2, n),
                         rng.uniform(-2, 2, n)]).astype(np.float32)
    Y = np.column_stack([-0.1 * X[:, 1], 0.1 * X[:, 0], 0.2 * X[:, 3] - 0.3 * X[:, 1]])
    return X, Y.astype(np.float32)


def paper_agent(data=None, horizon=3):
    """The construction lines of the paper's pendulum script."""
    X, Y = transitions() if data is None else data
    state_dim = Y.shape[1]
    control_dim = X.shape[1] - state_dim
    controller = RbfController(state_dim=state_dim, control_dim=control_dim,
                               num_basis_functions=2, max_action=2.0)
    R = ExponentialReward(state_dim=state_dim, t=TARGET, W=W)
    return PILCO((X, Y), controller=controller, horizon=horizon, reward=R,
                 m_init=M_INIT, S_init=S_INIT)


def fix_noise(pilco, value=1e-3):
    for model in pilco.mgpr.models:
        model.likelihood.variance.assign(value)
        set_trainable(model.likelihood.variance, False)


def test_fixed_noise_stays_fixed_through_model_restarts():
    """``likelihood.variance.assign`` + ``set_trainable(..., False)``: the noise is the
    user's value after training with restarts (a restart must not draw a new one), and
    the trainable hyperparameters did move."""
    pilco = paper_agent()
    fix_noise(pilco, 1e-3)
    before = [m.kernel.lengthscales.numpy().copy() for m in pilco.mgpr.models]
    pilco.optimize_models(maxiter=5, restarts=3, seed=0)
    for model, ell in zip(pilco.mgpr.models, before):
        assert float(model.likelihood.variance.numpy()) == pytest.approx(1e-3, rel=1e-12)
        assert not model.likelihood.variance.trainable
        assert not np.allclose(model.kernel.lengthscales.numpy(), ell)
    # a restart starts the free hyperparameters afresh and leaves the fixed one alone
    pilco.mgpr.initialize_hyperparameters(np.random.default_rng(1), spread=0.5)
    assert all(float(m.likelihood.variance.numpy()) == pytest.approx(1e-3, rel=1e-12)
               for m in pilco.mgpr.models)


def test_np_random_seed_makes_a_paper_script_repeatable():
    """The paper's scripts start with ``np.random.seed(0)``: the unseeded draws (initial
    policy, model and policy restarts) then repeat; another seed draws other values."""
    def new_controller(seed):
        np.random.seed(seed)
        return RbfController(state_dim=3, control_dim=1, num_basis_functions=2).centers.numpy()

    np.testing.assert_array_equal(new_controller(3), new_controller(3))
    assert not np.allclose(new_controller(3), new_controller(4))

    pilco = paper_agent()  # one agent: its compiled rollout is traced once
    start = (gpflow.utilities.read_values(pilco.mgpr), gpflow.utilities.read_values(pilco.controller))

    def train(seed):
        gpflow.utilities.multiple_assign(pilco.mgpr, start[0])
        gpflow.utilities.multiple_assign(pilco.controller, start[1])
        np.random.seed(seed)
        pilco.optimize_models(maxiter=2, restarts=2)
        pilco.optimize_policy(maxiter=2, restarts=2)
        return pilco.mgpr.hyperparameters()[0].numpy(), pilco.controller.centers.numpy()

    first, again, other = train(3), train(3), train(4)
    for a, b in zip(first, again):
        np.testing.assert_array_equal(a, b)
    assert not np.allclose(first[1], other[1])
