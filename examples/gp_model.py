"""MGPR as a GPflow model: fit two outputs of a 2-D function and predict, GPflow's way.

    python examples/gp_model.py
"""
import gpflow
import numpy as np
import tensorflow as tf

from pilco.models import MGPR

# A data set: 60 noisy observations of two functions of a 2-D input.
rng = np.random.default_rng(0)
X = rng.uniform(-3.0, 3.0, (60, 2))
Y = np.c_[np.sin(X[:, 0]) + 0.5 * X[:, 1], np.cos(X[:, 0] * X[:, 1] / 3.0)]
Y += 0.05 * rng.standard_normal(Y.shape)

# One GP per output; hyperparameters start from the data.
model = MGPR((X, Y))

# Train with GPflow's optimiser on the model's training loss (model.optimize() does the
# same, with restarts and safeguards).
gpflow.optimizers.Scipy().minimize(model.training_loss, model.trainable_variables)
gpflow.utilities.print_summary(model)

# Predict at new inputs: the latent function, then new observations (noise included).
Xnew = np.array([[0.0, 0.0], [1.0, -2.0], [2.5, 2.5]])
mean, var = model.predict_f(Xnew)
_, var_y = model.predict_y(Xnew)
print("predict_f mean:\n", mean.numpy())
print("predict_y variance (>= predict_f's):\n", var_y.numpy())

# How well does the model explain held-out data?
X_test = rng.uniform(-3.0, 3.0, (20, 2))
Y_test = np.c_[np.sin(X_test[:, 0]) + 0.5 * X_test[:, 1], np.cos(X_test[:, 0] * X_test[:, 1] / 3.0)]
print("mean log density of held-out points:",
      float(tf.reduce_mean(model.predict_log_density((X_test, Y_test)))))

# Predictions compile like any GPflow model's; PILCO's own use: a Gaussian input.
predict = tf.function(model.predict_f)
print("compiled predict_f agrees:", np.allclose(predict(tf.constant(Xnew))[0], mean))
M, S, V = model.predict_on_noisy_inputs(np.array([[1.0, -2.0]]), 0.05 * np.eye(2))
print("mean and covariance at x ~ N([1, -2], 0.05 I):\n", M.numpy(), "\n", S.numpy())
