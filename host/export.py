"""Export a trained scikit-learn pipeline into a device model bundle (see edge.model.bundle).

The golden MLP outputs are computed here with scikit-learn's own ``predict``; the device
re-computes them with the NumPy forward pass in :mod:`edge.estimation.mlp`, so the two independent
implementations must agree before a bundle is accepted.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from edge.estimation.estimate import mlp_golden_check
from edge.model.bundle import Bundle, write_bundle
from edge.estimation.mlp import ACTIVATION_CODES, MLP

MLP_ARRAY_PREFIX = "mlp_"


def mlp_arrays_from_sklearn(mlp: Any) -> dict[str, np.ndarray]:
    """Plain arrays (``mlp_n_layers``, ``mlp_W{i}``, ``mlp_b{i}``, activation codes) of a fitted
    ``sklearn.neural_network.MLPRegressor``.

    Raises
    ------
    ValueError
        Not fitted, not float64, unsupported activation, or more than one output.
    """
    for attr in ("coefs_", "intercepts_", "activation", "out_activation_"):
        if not hasattr(mlp, attr):
            raise ValueError(f"mlp: missing attribute {attr!r} (not a fitted MLPRegressor?)")
    if mlp.activation not in ACTIVATION_CODES:
        raise ValueError(f"mlp.activation: {mlp.activation!r} not supported; use one of {sorted(ACTIVATION_CODES)}")
    if mlp.out_activation_ not in ACTIVATION_CODES:
        raise ValueError(f"mlp.out_activation_: {mlp.out_activation_!r} not supported")
    for i, (w, b) in enumerate(zip(mlp.coefs_, mlp.intercepts_)):
        if np.asarray(w).dtype != np.float64 or np.asarray(b).dtype != np.float64:
            raise ValueError(
                f"mlp.coefs_[{i}]/intercepts_[{i}]: dtype {np.asarray(w).dtype}; train on float64 data "
                "so the device reproduces the host to 1e-9"
            )
    if np.asarray(mlp.coefs_[-1]).shape[1] != 1:
        raise ValueError(f"mlp: the bundle schema wants one output, model has {np.asarray(mlp.coefs_[-1]).shape[1]}")
    net = MLP(mlp.coefs_, mlp.intercepts_, mlp.activation, mlp.out_activation_)
    return net.to_arrays(MLP_ARRAY_PREFIX)


def pca_arrays_from_sklearn(pca: Any) -> dict[str, np.ndarray]:
    """``pca_mean``, ``pca_components``, ``pca_explained_variance_ratio`` of a fitted
    ``sklearn.decomposition.PCA`` (whitening is refused: the device does not undo it)."""
    if getattr(pca, "whiten", False):
        raise ValueError("pca.whiten: whitened PCA is not supported by the bundle schema")
    return {
        "pca_mean": np.asarray(pca.mean_, dtype=np.float64),
        "pca_components": np.asarray(pca.components_, dtype=np.float64),
        "pca_explained_variance_ratio": np.asarray(pca.explained_variance_ratio_, dtype=np.float64),
    }


def export_paper_model(
    path: str | os.PathLike,
    mlp: Any,
    preprocessing: Mapping[str, Any],
    golden_inputs: np.ndarray,
    metrics: Mapping[str, Any],
    training_set_sha256: str,
    extra_arrays: Mapping[str, Any] | None = None,
    *,
    extra_golden: Mapping[str, Any] | None = None,
    description: str = "Ma & Zhang (2024) BP network: ln-features -> norm -> PCA -> MLP -> k",
    model_version: str = "0",
    created_utc: str | None = None,
    overwrite: bool = False,
    golden_check=None,
    golden_rtol: float | None = None,
) -> Bundle:
    """Write a bundle for the paper's pipeline (section 3.2) from a fitted MLPRegressor.

    Parameters
    ----------
    path : path-like
        Bundle directory to create.
    mlp : sklearn.neural_network.MLPRegressor
        Fitted on float64 PCA scores; single output.
    preprocessing : mapping
        ``feature_version``, ``x_log_offset``, ``x_mean``, ``x_scale``, ``pca_mean``,
        ``pca_components``, ``pca_explained_variance_ratio``, ``y_transform`` (see
        :mod:`edge.model.schema`); :func:`pca_arrays_from_sklearn` fills the PCA ones.
    golden_inputs : array_like, shape (n_golden, n_components)
        MLP inputs (PCA scores) whose outputs the device must reproduce.
    metrics : mapping
        Validation metrics (JSON-serialisable, finite).
    training_set_sha256 : str
        SHA-256 (hex) of the training data set.
    extra_arrays : mapping, optional
        Further declared arrays (material library, prior coefficients, ...).
    extra_golden : mapping, optional
        Further golden vectors (e.g. end-to-end pipeline inputs/outputs) declared in the schema.
    golden_check, golden_rtol : optional
        Passed to :func:`edge.model.bundle.write_bundle` (defaults: MLP check, 1e-9).

    Returns
    -------
    Bundle
        The written, verified bundle.
    """
    mlp_arrays = mlp_arrays_from_sklearn(mlp)
    arrays: dict[str, Any] = dict(preprocessing)
    clash = sorted(set(extra_arrays or {}) & set(arrays))
    if clash:
        raise ValueError(f"extra_arrays: arrays {clash} also given in preprocessing")
    arrays.update(extra_arrays or {})
    clash = sorted(set(mlp_arrays) & set(arrays))
    if clash:
        raise ValueError(f"preprocessing/extra_arrays: {clash} are taken from the MLP itself")
    arrays.update(mlp_arrays)

    x = np.asarray(golden_inputs, dtype=np.float64)
    if x.ndim != 2 or x.shape[0] == 0:
        raise ValueError(f"golden_inputs: expected a non-empty 2-D array (n_golden, n_components), got {x.shape}")
    n_in = int(mlp_arrays["mlp_W0"].shape[0])
    if x.shape[1] != n_in:
        raise ValueError(f"golden_inputs: the MLP takes {n_in} inputs (PCA scores), got {x.shape[1]} columns")
    golden: dict[str, Any] = {"mlp_inputs": x, "mlp_outputs": np.asarray(mlp.predict(x), dtype=np.float64).reshape(-1)}
    if extra_golden:
        clash = sorted(set(extra_golden) & set(golden))
        if clash:
            raise ValueError(f"extra_golden: {clash} are computed by the exporter")
        golden.update(extra_golden)

    manifest_extra: dict[str, Any] = {
        "training_set_sha256": str(training_set_sha256).lower(),
        "metrics": dict(metrics),
        "description": description,
        "model_version": model_version,
        "exporter": {"sklearn_class": type(mlp).__name__, "hidden_layer_sizes": [int(w.shape[1]) for w in mlp.coefs_[:-1]]},
    }
    if created_utc is not None:
        manifest_extra["created_utc"] = created_utc
    kwargs: dict[str, Any] = {}
    if golden_check is not None:
        kwargs["golden_check"] = golden_check
    if golden_rtol is not None:
        kwargs["golden_rtol"] = golden_rtol
    kwargs.setdefault("golden_check", mlp_golden_check)
    return write_bundle(path, arrays, golden, manifest_extra, overwrite=overwrite, **kwargs)
