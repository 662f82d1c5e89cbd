"""RbfController.place_near: the MATLAB release's initial policy around a state distribution,
shared by the reacher and cart-pole tasks."""
import numpy as np
import pytest

from pilco.controllers import RbfController, StartDraw
from pilco.features import angle_features
from pilco.tasks import cartpole


def test_centres_are_drawn_around_the_mean_and_targets_are_small():
    mean = np.array([-1.0, 2.0, 0.5])
    c = RbfController(3, 2, 4000, seed=0)
    lengthscales = c.models[0].kernel.lengthscales.numpy().copy()
    c.place_near(mean, 0.3, seed=1)
    centers, targets = c.centers.numpy(), c.targets.numpy()
    assert centers.shape == (4000, 3) and targets.shape == (4000, 2)
    # sample moments of 4000 draws: mean within 4 standard errors, std within 5 %
    np.testing.assert_allclose(centers.mean(axis=0), mean, atol=4 * 0.3 / np.sqrt(4000))
    np.testing.assert_allclose(centers.std(axis=0), 0.3, rtol=0.05)
    np.testing.assert_allclose(targets.std(axis=0), 0.1, rtol=0.05)
    np.testing.assert_array_equal(c.models[0].kernel.lengthscales.numpy(), lengthscales)
    # the same seed, the same policy; another seed, another one
    again = RbfController(3, 2, 4000, seed=5)
    again.place_near(mean, 0.3, seed=1)
    np.testing.assert_array_equal(again.centers.numpy(), centers)
    again.place_near(mean, 0.3, seed=2)
    assert not np.allclose(again.centers.numpy(), centers)


def test_zero_std_puts_every_centre_on_the_mean():
    c = RbfController(2, 1, 5, seed=0)
    c.place_near([0.5, -0.5], 0.0, seed=3, target_std=0.0)
    np.testing.assert_array_equal(c.centers.numpy(), np.tile([0.5, -0.5], (5, 1)))
    np.testing.assert_array_equal(c.targets.numpy(), np.zeros((5, 1)))


def test_features_map_the_drawn_states_to_policy_inputs():
    # the cart-pole draws [x, dx, dtheta, theta] and feeds (sin theta, cos theta)
    c = RbfController(5, 1, 200, seed=0)
    cartpole.init_policy_from_start(c, 0.1, seed=4)
    centers = c.centers.numpy()
    np.testing.assert_allclose(centers[:, 3] ** 2 + centers[:, 4] ** 2, 1.0, rtol=1e-12)
    assert np.all(centers[:, 4] > 0.9)  # theta near 0 (hanging down): cos theta near 1
    np.testing.assert_allclose(c.models[0].kernel.lengthscales.numpy(),
                               [1.0, 1.0, 1.0, 0.7, 0.7], rtol=1e-12)
    direct = RbfController(5, 1, 200, seed=0)
    direct.place_near(np.zeros(4), 0.1, seed=4, features=lambda x: angle_features(x, [3]))
    np.testing.assert_array_equal(direct.centers.numpy(), centers)


def test_a_start_draw_is_place_near_with_its_lengthscales_and_refuses_bad_settings():
    draw = StartDraw([0.0, 1.0, 0.0], 0.2, [0.5, 0.6, 0.7, 0.8], angle_indices=[1])
    c = RbfController(4, 1, 6, seed=0)
    draw(c, 5)
    direct = RbfController(4, 1, 6, seed=0)
    direct.place_near([0.0, 1.0, 0.0], 0.2, seed=5, features=lambda x: angle_features(x, [1]))
    np.testing.assert_array_equal(c.centers.numpy(), direct.centers.numpy())
    np.testing.assert_array_equal(c.targets.numpy(), direct.targets.numpy())
    np.testing.assert_allclose(c.models[0].kernel.lengthscales.numpy(), [0.5, 0.6, 0.7, 0.8],
                               rtol=1e-12)
    assert StartDraw.from_dict(draw.to_dict()) == draw
    assert StartDraw.from_dict({**draw.to_dict(), "std": 0.3}) != draw
    with pytest.raises(ValueError, match="lengthscales must have 4 entries, got 3"):
        StartDraw([0.0, 1.0, 0.0], 0.2, [1.0, 1.0, 1.0], angle_indices=[1])
    with pytest.raises(ValueError, match="lengthscales must be positive"):
        StartDraw([0.0, 1.0, 0.0], 0.2, [1.0, 1.0, 0.0, 1.0], angle_indices=[1])
    with pytest.raises(ValueError, match="angle_indices: index 3 is outside the state "
                                         "\\(dimension 3\\)"):
        StartDraw([0.0, 1.0, 0.0], 0.2, [1.0] * 4, angle_indices=[3])
    with pytest.raises(ValueError, match="mean"):
        StartDraw([0.0, np.nan, 0.0], 0.2, [1.0] * 3)
    with pytest.raises(ValueError, match="std"):
        StartDraw([0.0], -1.0, [1.0])
    with pytest.raises(ValueError, match="this draw has 4 policy inputs, the controller 3"):
        draw(RbfController(3, 1, 6, seed=0), 1)

