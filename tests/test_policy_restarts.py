"""Policy restarts (``optimize_policy(restarts=k)``): the first run continues from the
current policy, every further run starts from ``controller.randomize``, and the best
policy evaluated by any run is the one left in place and returned."""
import numpy as np
import pytest

from pilco.controllers import RbfController
from pilco.models import PILCO
from pilco.rewards import ExponentialReward

D, U = 2, 1


def make_agent():
    rng = np.random.default_rng(3)
    X = rng.uniform(-1.0, 1.0, (30, D + U))
    # a smooth system: the state moves by the action and decays a little
    Y = np.column_stack([0.3 * X[:, 2] - 0.1 * X[:, 0], 0.2 * X[:, 2] - 0.1 * X[:, 1]])
    controller = RbfController(D, U, 5, max_action=1.0, seed=0)
    reward = ExponentialReward(D, W=np.eye(D), t=np.array([[0.5, 0.3]]))
    agent = PILCO((X, Y), controller, reward, horizon=5, m_init=np.zeros((1, D)),
                  S_init=0.01 * np.eye(D))
    agent.optimize_models(maxiter=30, seed=0)
    return agent


def parameters(agent):
    return [v.numpy().copy() for v in agent.controller.trainable_variables]


def put(agent, values):
    for v, value in zip(agent.controller.trainable_variables, values):
        v.assign(value)


@pytest.fixture(scope="module")
def shared():
    """One trained model (tracing is paid once); each test starts from its first policy."""
    agent = make_agent()
    return agent, parameters(agent)


@pytest.fixture
def agent(shared):
    agent, start = shared
    put(agent, start)
    return agent


def test_later_restarts_that_end_worse_do_not_replace_the_first_runs_policy(agent,
                                                                            monkeypatch):
    """Restarts whose start is made useless (zero weights, tiny lengthscales: no action
    anywhere, no gradient) end worse than the continued run; its policy must stay."""
    start = parameters(agent)
    single = agent.optimize_policy(maxiter=10, restarts=1, seed=0)
    single_policy = parameters(agent)
    put(agent, start)

    calls = []

    def useless_start(seed=None):
        calls.append(seed)
        c = agent.controller
        c.targets.assign(np.zeros(c.targets.shape))
        c.centers.assign(np.full(c.centers.shape, 50.0))
        for g in c.models:
            g.kernel.lengthscales.assign(np.full(D, 0.05))

    monkeypatch.setattr(agent.controller, "randomize", useless_start)
    best = agent.optimize_policy(maxiter=10, restarts=3, seed=0)
    assert len(calls) == 2
    assert np.isclose(best, single, rtol=1e-9)
    assert np.isclose(agent.expected_return(), best, rtol=1e-9)
    for v, value in zip(parameters(agent), single_policy):
        np.testing.assert_allclose(v, value, rtol=1e-9, atol=1e-12)


def test_a_better_restart_replaces_the_first_runs_policy(agent, monkeypatch):
    """A restart that starts from a better policy than the first run reaches wins."""
    start = parameters(agent)
    agent.optimize_policy(maxiter=30, restarts=1, seed=0)
    good, good_return = parameters(agent), agent.expected_return()
    put(agent, start)
    first_only = agent.optimize_policy(maxiter=1, restarts=1, seed=0)
    put(agent, start)
    assert good_return > first_only  # the constructed case: the restart's start is better

    def good_start(seed=None):
        put(agent, good)

    monkeypatch.setattr(agent.controller, "randomize", good_start)
    best = agent.optimize_policy(maxiter=1, restarts=2, seed=0)
    assert best >= good_return - 1e-9
    assert np.isclose(agent.expected_return(), best, rtol=1e-9)


def test_restarts_are_repeatable_with_a_seed(agent):
    start = parameters(agent)
    first = agent.optimize_policy(maxiter=5, restarts=2, seed=7)
    first_policy = parameters(agent)
    put(agent, start)
    assert agent.optimize_policy(maxiter=5, restarts=2, seed=7) == first
    for x, y in zip(parameters(agent), first_policy):
        np.testing.assert_array_equal(x, y)


def test_a_controllers_randomizer_draws_the_restarts(agent):
    """With ``randomizer`` set, every restart's policy comes from it (with a seed of the
    search's generator); without it, ``randomize`` draws its own."""
    seeds = []

    def near_zero(controller, seed):
        seeds.append(seed)
        rng = np.random.default_rng(seed)
        controller.set_data((0.01 * rng.standard_normal((5, D)), np.zeros((5, U))))

    agent.controller.randomizer = near_zero
    try:
        agent.optimize_policy(maxiter=2, restarts=3, seed=4)
        assert len(seeds) == 2 and len(set(seeds)) == 2
        agent.controller.randomize(seed=7)
        assert seeds[-1] == 7
        assert np.abs(agent.controller.centers.numpy()).max() < 0.1
    finally:
        agent.controller.randomizer = None
    agent.controller.randomize(seed=7)
    assert np.abs(agent.controller.centers.numpy()).max() > 0.1  # N(0, I) centres


def test_the_cartpoles_restarts_are_drawn_as_its_initial_policy(tmp_path):
    from pilco.tasks.cartpole import CARTPOLE

    s = CARTPOLE.parse(["--output", str(tmp_path), "--seed", "3"])
    rng = np.random.default_rng(0)
    X, Y = rng.normal(size=(20, 5)), 0.01 * rng.normal(size=(20, 4))
    controller = CARTPOLE.agent_builder(s, None)((X, Y), None).controller
    controller.models[0].kernel.lengthscales.assign(np.full(5, 3.0))
    controller.randomize(seed=11)
    centers = controller.centers.numpy()  # [x, dx, dtheta, sin theta, cos theta]
    assert np.abs(centers[:, :4]).max() < 0.5 and np.all(centers[:, 4] > 0.9)
    np.testing.assert_allclose(controller.models[0].kernel.lengthscales.numpy(),
                               [1.0, 1.0, 1.0, 0.7, 0.7])
    random = CARTPOLE.agent_builder(CARTPOLE.parse(["--output", str(tmp_path),
                                                    "--policy-init", "random"]), None)
    assert random((X, Y), None).controller.randomizer is None


def test_a_saved_cartpole_agent_restarts_as_the_run_did(tmp_path):
    """The cart-pole's restart draw is saved with its agent: a resumed run (or its
    diagnosis) loads an agent whose restarts are the built agent's, draw for draw."""
    from pilco.controllers import StartDraw
    from pilco.models import PILCO
    from pilco.tasks.cartpole import CARTPOLE, start_draw

    s = CARTPOLE.parse(["--output", str(tmp_path), "--seed", "3"])
    rng = np.random.default_rng(0)
    X, Y = rng.normal(size=(20, 5)), 0.01 * rng.normal(size=(20, 4))
    built = CARTPOLE.agent_builder(s, None)((X, Y), None)
    assert built.controller.randomizer == start_draw(0.1)
    built.save(str(tmp_path / "agent.npz"))
    loaded = PILCO.load(str(tmp_path / "agent.npz"))
    assert isinstance(loaded.controller.randomizer, StartDraw)
    for agent in (built, loaded):
        agent.controller.randomize(seed=11)
    for a, b in zip(built.controller.trainable_variables,
                    loaded.controller.trainable_variables):
        np.testing.assert_array_equal(a.numpy(), b.numpy())


def test_a_randomizer_that_is_not_a_start_draw_is_not_saved(agent, tmp_path, caplog):
    from pilco.models import PILCO

    agent.controller.randomizer = lambda controller, seed: None
    try:
        with caplog.at_level("WARNING", logger="pilco.models.storage"):
            agent.save(str(tmp_path / "agent.npz"))
            agent.save(str(tmp_path / "agent.npz"))  # said once, not at every save
    finally:
        agent.controller.randomizer = None
    assert caplog.text.count("is not saved") == 1
    assert PILCO.load(str(tmp_path / "agent.npz")).controller.randomizer is None


def test_each_runs_best_return_is_kept_and_can_be_put_in_place(agent):
    """``policy_run_returns`` lists each run's best expected return (the best of them is
    what the search returned); ``use_policy_run(r)`` puts run r's best policy in place,
    and the model then predicts exactly that return for it."""
    best = agent.optimize_policy(maxiter=5, restarts=3, seed=4)
    returns = agent.policy_run_returns
    assert len(returns) == 3
    assert np.isclose(max(returns), best, rtol=1e-12)
    left = parameters(agent)
    for run in range(3):
        assert np.isclose(agent.use_policy_run(run), returns[run], rtol=1e-12)
        assert np.isclose(agent.expected_return(), returns[run], rtol=1e-9)
    winner = int(np.argmax(returns))
    agent.use_policy_run(winner)
    for v, value in zip(parameters(agent), left):
        np.testing.assert_allclose(v, value, rtol=1e-12)


def test_use_policy_run_rejects_runs_that_do_not_exist(agent):
    agent.optimize_policy(maxiter=2, restarts=2, seed=1)
    for bad in (2, -1, True, 1.0, "0"):
        with pytest.raises(ValueError, match="run must be an index into the last policy "
                                             "search's 2 run"):
            agent.use_policy_run(bad)
