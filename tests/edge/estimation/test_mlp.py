import warnings

import numpy as np
import pytest

from edge.estimation.mlp import ACTIVATION_CODES, MLP

# scikit-learn: one worker pays for its import (tests/support/schedule.py).
pytestmark = pytest.mark.shares_import("sklearn")


def _fit(activation: str, hidden=(100, 20), seed: int = 0, n_in: int = 2) -> "MLPRegressor":  # noqa: F821
    # scikit-learn (1.2 s to import, SciPy's stats the most of it) only where a test fits: every
    # xdist worker imports every test module to collect, most never run one of these.
    from sklearn.exceptions import ConvergenceWarning
    from sklearn.neural_network import MLPRegressor

    rng = np.random.default_rng(seed)
    X = rng.normal(size=(80, n_in))
    y = np.sin(X[:, 0]) + 0.5 * X[:, -1] ** 2 + 0.1 * rng.normal(size=80)
    model = MLPRegressor(hidden_layer_sizes=hidden, activation=activation, max_iter=60, random_state=seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        model.fit(X, y)
    return model


def _max_rel(a, b):
    return float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-300)))


@pytest.mark.parametrize("activation", ["tanh", "relu", "logistic", "identity"])
def test_forward_pass_matches_sklearn(activation):
    model = _fit(activation)
    net = MLP(model.coefs_, model.intercepts_, model.activation, model.out_activation_)
    X = np.random.default_rng(7).normal(scale=3.0, size=(500, 2))
    got, want = net.predict(X), model.predict(X)
    assert got.shape == want.shape == (500,)
    assert _max_rel(got, want) <= 1e-9


def test_paper_topology_three_hidden_layers_and_wide_input():
    # (100, 20) is the paper's network; also check a deeper one with more inputs.
    model = _fit("tanh", hidden=(30, 20, 10), n_in=8, seed=3)
    net = MLP(model.coefs_, model.intercepts_, "tanh")
    X = np.random.default_rng(1).normal(size=(200, 8))
    assert net.n_inputs == 8 and net.n_layers == 4 and net.n_outputs == 1
    assert _max_rel(net.predict(X), model.predict(X)) <= 1e-9


def test_round_trip_through_arrays_and_codes():
    model = _fit("relu")
    net = MLP(model.coefs_, model.intercepts_, "relu")
    arrays = net.to_arrays()
    assert int(arrays["mlp_n_layers"]) == 3
    assert int(arrays["mlp_hidden_activation"]) == ACTIVATION_CODES["relu"]
    assert arrays["mlp_W0"].shape == (2, 100) and arrays["mlp_b2"].shape == (1,)
    net2 = MLP.from_arrays(arrays)
    X = np.random.default_rng(2).normal(size=(50, 2))
    np.testing.assert_array_equal(net2.predict(X), net.predict(X))
    assert net2.hidden_activation == "relu"


def test_single_sample_and_multi_output():
    rng = np.random.default_rng(4)
    net = MLP([rng.normal(size=(3, 5)), rng.normal(size=(5, 2))], [np.zeros(5), np.ones(2)], "tanh")
    x = rng.normal(size=3)
    y1 = net.predict(x)
    assert y1.shape == (2,)
    np.testing.assert_allclose(y1, np.tanh(x @ net.weights[0]) @ net.weights[1] + 1.0, rtol=1e-14)
    assert net.predict(rng.normal(size=(4, 3))).shape == (4, 2)


def test_logistic_is_stable_for_large_inputs():
    net = MLP([np.array([[1.0]]), np.array([[1.0]])], [np.zeros(1), np.zeros(1)], "logistic")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no overflow warnings
        out = net.predict(np.array([[-1000.0], [0.0], [1000.0]]))
    np.testing.assert_allclose(out, [0.0, 0.5, 1.0], atol=1e-300)


def test_weights_are_read_only_copies():
    w = np.ones((2, 1))
    net = MLP([w], [np.zeros(1)], "identity")
    w[:] = 5.0
    assert net.predict(np.array([1.0, 1.0])) == 2.0
    with pytest.raises(ValueError):
        net.weights[0][0, 0] = 3.0


@pytest.mark.parametrize(
    "weights,biases,act,match",
    [
        ([np.ones((2, 3)), np.ones((4, 1))], [np.ones(3), np.ones(1)], "tanh", "weights\\[1\\]"),
        ([np.ones((2, 3))], [np.ones(2)], "tanh", "biases\\[0\\]"),
        ([np.ones((2, 3))], [np.ones(3), np.ones(3)], "tanh", "weights/biases"),
        ([np.ones((2, 1))], [np.ones(1)], "softmax", "hidden_activation"),
        ([np.ones((2, 1))], [np.ones(1)], 7, "hidden_activation"),
        ([np.full((2, 1), np.nan)], [np.ones(1)], "tanh", "NaN"),
        ([], [], "tanh", "at least one layer"),
    ],
)
def test_bad_construction_names_the_problem(weights, biases, act, match):
    with pytest.raises(ValueError, match=match):
        MLP(weights, biases, act)


def test_predict_rejects_wrong_input_width():
    net = MLP([np.ones((2, 1))], [np.zeros(1)], "identity")
    with pytest.raises(ValueError, match=r"X: expected shape \(n_samples, 2\)"):
        net.predict(np.ones((3, 4)))


def test_from_arrays_names_missing_array():
    arrays = MLP([np.ones((2, 1))], [np.zeros(1)], "identity").to_arrays()
    del arrays["mlp_b0"]
    with pytest.raises(ValueError, match="mlp_b0"):
        MLP.from_arrays(arrays)
