"""Multilayer-perceptron forward pass from plain arrays (the paper's BP network, section 3.2).

The network is stored as weight matrices and bias vectors only, so the probe can run it with
NumPy alone. The arithmetic follows scikit-learn's ``MLPRegressor`` forward pass (``X @ W + b``
per layer, hidden activation on every layer but the last, then the output activation) so that
predictions agree with the training host to rounding error.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from edge.model.schema import ACTIVATION_CODES, ACTIVATION_NAMES



def _identity(z: np.ndarray) -> np.ndarray:
    return z


def _tanh(z: np.ndarray) -> np.ndarray:
    return np.tanh(z, out=z)


def _relu(z: np.ndarray) -> np.ndarray:
    return np.maximum(z, 0.0, out=z)


def _logistic(z: np.ndarray) -> np.ndarray:
    # Split by sign so exp never overflows: for z < 0 use e^z / (1 + e^z).
    out = np.empty_like(z)
    pos = z >= 0
    out[pos] = 1.0 / (1.0 + np.exp(-z[pos]))
    ez = np.exp(z[~pos])
    out[~pos] = ez / (1.0 + ez)
    return out


_ACTIVATION_FUNCS = {"identity": _identity, "tanh": _tanh, "relu": _relu, "logistic": _logistic}


def _activation_name(value: str | int, argname: str) -> str:
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        if int(value) not in ACTIVATION_NAMES:
            raise ValueError(
                f"{argname}: unknown activation code {int(value)}; known codes {ACTIVATION_NAMES}"
            )
        return ACTIVATION_NAMES[int(value)]
    if isinstance(value, str) and value in ACTIVATION_CODES:
        return value
    raise ValueError(
        f"{argname}: unknown activation {value!r}; expected one of {sorted(ACTIVATION_CODES)} "
        f"or their codes {sorted(ACTIVATION_NAMES)}"
    )


class MLP:
    """Fully connected feed-forward network evaluated with NumPy.

    Parameters
    ----------
    weights : sequence of 2-D float arrays
        ``weights[i]`` has shape ``(n_in_i, n_out_i)`` (scikit-learn's ``coefs_`` layout);
        ``n_out_i`` must equal ``n_in_{i+1}``.
    biases : sequence of 1-D float arrays
        ``biases[i]`` has shape ``(n_out_i,)`` (scikit-learn's ``intercepts_``).
    hidden_activation : str or int
        ``'identity'``, ``'tanh'``, ``'relu'`` or ``'logistic'`` (or the code from
        :data:`ACTIVATION_CODES`), applied after every layer except the last.
    output_activation : str or int
        Activation of the last layer; ``'identity'`` for a regressor.

    Notes
    -----
    Arrays are copied to C-contiguous float64 and made read-only, so a model cannot be changed
    after construction.
    """

    def __init__(
        self,
        weights: Sequence[np.ndarray],
        biases: Sequence[np.ndarray],
        hidden_activation: str | int = "tanh",
        output_activation: str | int = "identity",
    ) -> None:
        if len(weights) == 0:
            raise ValueError("weights: need at least one layer")
        if len(weights) != len(biases):
            raise ValueError(
                f"weights/biases: {len(weights)} weight matrices but {len(biases)} bias vectors"
            )
        ws: list[np.ndarray] = []
        bs: list[np.ndarray] = []
        for i, (w, b) in enumerate(zip(weights, biases)):
            w = np.array(w, dtype=np.float64, order="C", copy=True)
            b = np.array(b, dtype=np.float64, order="C", copy=True)
            if w.ndim != 2:
                raise ValueError(f"weights[{i}]: expected a 2-D matrix, got shape {w.shape}")
            if b.shape != (w.shape[1],):
                raise ValueError(
                    f"biases[{i}]: expected shape ({w.shape[1]},) to match weights[{i}] "
                    f"{w.shape}, got {b.shape}"
                )
            if i > 0 and w.shape[0] != ws[-1].shape[1]:
                raise ValueError(
                    f"weights[{i}]: input size {w.shape[0]} does not match output size "
                    f"{ws[-1].shape[1]} of weights[{i - 1}]"
                )
            if not (np.all(np.isfinite(w)) and np.all(np.isfinite(b))):
                raise ValueError(f"weights[{i}]/biases[{i}]: contain NaN or inf")
            w.flags.writeable = False
            b.flags.writeable = False
            ws.append(w)
            bs.append(b)
        self.weights: tuple[np.ndarray, ...] = tuple(ws)
        self.biases: tuple[np.ndarray, ...] = tuple(bs)
        self.hidden_activation: str = _activation_name(hidden_activation, "hidden_activation")
        self.output_activation: str = _activation_name(output_activation, "output_activation")

    @property
    def n_inputs(self) -> int:
        """Number of input features."""
        return int(self.weights[0].shape[0])

    @property
    def n_outputs(self) -> int:
        """Number of outputs."""
        return int(self.weights[-1].shape[1])

    @property
    def n_layers(self) -> int:
        """Number of weight layers (hidden layers + 1)."""
        return len(self.weights)

    def predict(self, X: np.ndarray) -> np.ndarray:
        """Evaluate the network.

        Parameters
        ----------
        X : array_like, shape (n_samples, n_inputs) or (n_inputs,)
            Inputs. A 1-D array is one sample.

        Returns
        -------
        ndarray
            Shape ``(n_samples,)`` for a single-output network (as scikit-learn's
            ``MLPRegressor.predict``), else ``(n_samples, n_outputs)``. For 1-D input the sample
            axis is dropped (shape ``()`` or ``(n_outputs,)``).
        """
        a = np.asarray(X, dtype=np.float64)
        single = a.ndim == 1
        if single:
            a = a[np.newaxis, :]
        if a.ndim != 2 or a.shape[1] != self.n_inputs:
            raise ValueError(
                f"X: expected shape (n_samples, {self.n_inputs}) or ({self.n_inputs},), "
                f"got {np.shape(X)}"
            )
        hidden = _ACTIVATION_FUNCS[self.hidden_activation]
        last = self.n_layers - 1
        for i, (w, b) in enumerate(zip(self.weights, self.biases)):
            a = a @ w
            a += b
            if i != last:
                a = hidden(a)
        a = _ACTIVATION_FUNCS[self.output_activation](a)
        if self.n_outputs == 1:
            a = a.ravel()
        return a[0] if single else a

    def to_arrays(self, prefix: str = "mlp_") -> dict[str, np.ndarray]:
        """Plain-array form used in a model bundle.

        Returns
        -------
        dict
            ``{prefix}n_layers`` (int64 scalar), ``{prefix}W{i}``, ``{prefix}b{i}`` (float64),
            ``{prefix}hidden_activation`` and ``{prefix}output_activation`` (int64 codes).
        """
        out: dict[str, np.ndarray] = {f"{prefix}n_layers": np.array(self.n_layers, np.int64)}
        for i, (w, b) in enumerate(zip(self.weights, self.biases)):
            out[f"{prefix}W{i}"] = np.array(w)
            out[f"{prefix}b{i}"] = np.array(b)
        out[f"{prefix}hidden_activation"] = np.array(
            ACTIVATION_CODES[self.hidden_activation], np.int64
        )
        out[f"{prefix}output_activation"] = np.array(
            ACTIVATION_CODES[self.output_activation], np.int64
        )
        return out

    @classmethod
    def from_arrays(cls, arrays: Mapping[str, np.ndarray], prefix: str = "mlp_") -> "MLP":
        """Build from the plain-array form written by :meth:`to_arrays`.

        Raises
        ------
        ValueError
            If an array is missing (named in the message) or the layers do not chain.
        """

        def get(name: str) -> np.ndarray:
            key = prefix + name
            if key not in arrays:
                raise ValueError(f"arrays: missing {key!r}")
            return np.asarray(arrays[key])

        n = get("n_layers")
        if n.shape != () or n.dtype.kind not in "iu":
            raise ValueError(f"{prefix}n_layers: expected an integer scalar, got {n.dtype}{n.shape}")
        n_layers = int(n)
        if n_layers < 1:
            raise ValueError(f"{prefix}n_layers: must be >= 1, got {n_layers}")
        weights = [get(f"W{i}") for i in range(n_layers)]
        biases = [get(f"b{i}") for i in range(n_layers)]
        return cls(
            weights,
            biases,
            hidden_activation=int(get("hidden_activation")),
            output_activation=int(get("output_activation")),
        )

    def __repr__(self) -> str:
        sizes = [self.n_inputs] + [int(w.shape[1]) for w in self.weights]
        return (
            f"MLP(layer_sizes={sizes}, hidden_activation={self.hidden_activation!r}, "
            f"output_activation={self.output_activation!r})"
        )
