import hashlib
import warnings

import numpy as np
import pytest

from edge.estimation.mlp import MLP
from edge.estimation.estimate import mlp_golden_check
from edge.model import bundle as B
from edge.model.schema import ArraySpec, SCHEMAS
from host.export import export_paper_model, mlp_arrays_from_sklearn, pca_arrays_from_sklearn

# scikit-learn: one worker pays for its import (tests/support/schedule.py).
pytestmark = pytest.mark.shares_import("sklearn")


@pytest.fixture(scope="module")
def trained():
    """Paper-shaped pipeline on synthetic data: 8 ln-features -> z-score -> PCA(2) -> MLP(100, 20)."""
    # scikit-learn is imported where it is used (1.2 s): every xdist worker collects this module.
    from sklearn.decomposition import PCA
    from sklearn.exceptions import ConvergenceWarning
    from sklearn.neural_network import MLPRegressor

    rng = np.random.default_rng(0)
    u = np.exp(rng.normal(size=(120, 8)) + np.linspace(0, 1, 8))
    lx = np.log(u)
    mean, scale = lx.mean(0), lx.std(0)
    x = (lx - mean) / scale
    pca = PCA(n_components=2, random_state=0).fit(x)
    p = pca.transform(x)
    y = np.log(0.1 + np.exp(p[:, 0]))
    mlp = MLPRegressor(hidden_layer_sizes=(100, 20), activation="tanh", max_iter=80, random_state=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        mlp.fit(p, y)
    pre = {
        "feature_version": 1,
        "x_log_offset": np.zeros(8),
        "x_mean": mean,
        "x_scale": scale,
        "y_transform": 1,
        **pca_arrays_from_sklearn(pca),
    }
    return mlp, pca, pre, p


def _export(path, trained, **kw):
    mlp, _pca, pre, p = trained
    args = dict(
        golden_inputs=p[:10],
        metrics={"val_mape": 0.031},
        training_set_sha256=hashlib.sha256(b"data").hexdigest(),
        model_version="2024.1",
        created_utc="2024-05-01T00:00:00Z",
    )
    args.update(kw)
    return export_paper_model(path, mlp, pre, **args)


def test_export_then_edge_reproduces_sklearn(tmp_path, trained):
    mlp, pca, _pre, p = trained
    b = _export(tmp_path / "paper", trained)
    loaded = B.load_bundle(tmp_path / "paper", golden_check=mlp_golden_check)
    assert loaded.sha256 == b.sha256
    assert loaded.manifest["metrics"] == {"val_mape": 0.031}
    assert loaded.manifest["exporter"]["hidden_layer_sizes"] == [100, 20]
    np.testing.assert_array_equal(loaded.arrays["pca_components"], pca.components_)
    net = MLP.from_arrays(loaded.arrays)
    X = np.random.default_rng(3).normal(size=(300, 2))
    ref = mlp.predict(X)
    assert np.max(np.abs(net.predict(X) - ref) / np.abs(ref)) <= 1e-9
    # Golden outputs came from sklearn, not from the edge code.
    np.testing.assert_array_equal(loaded.golden["mlp_outputs"], mlp.predict(p[:10]))


def test_export_with_library_tables(tmp_path, trained):
    lib = {
        "lib_effusivity": np.array([1570.0, 24000.0]),
        "lib_k": np.array([1.097, 237.0]),
        "lib_rho_c": np.array([2458.4 * 809, 2700 * 897.0]),
        "lib_names": np.array(["tempered glass", "aluminium"]),
        "lib_class": np.array(["glass", "metal"]),
    }
    b = _export(tmp_path / "lib", trained, extra_arrays=lib)
    assert b.dims["n_materials"] == 2
    with pytest.raises(ValueError, match="also given in preprocessing"):
        _export(tmp_path / "dup", trained, extra_arrays={"x_mean": np.zeros(8)})


def test_extra_golden_must_be_declared(tmp_path, trained):
    with pytest.raises(B.UnknownArrayError, match="pipeline_inputs"):
        _export(tmp_path / "g", trained, extra_golden={"pipeline_inputs": np.zeros((3, 8))})
    SCHEMAS[1].golden["zz_pipeline_inputs"] = ArraySpec("f", ("n_pipeline", "n_features"), required=False)
    try:
        b = _export(tmp_path / "g2", trained, extra_golden={"zz_pipeline_inputs": np.zeros((3, 8))})
        assert b.golden["zz_pipeline_inputs"].shape == (3, 8)
    finally:
        del SCHEMAS[1].golden["zz_pipeline_inputs"]


def test_export_refusals(tmp_path, trained):
    from sklearn.decomposition import PCA
    from sklearn.exceptions import ConvergenceWarning
    from sklearn.neural_network import MLPRegressor

    mlp, pca, pre, p = trained
    with pytest.raises(ValueError, match="coefs_"):
        mlp_arrays_from_sklearn(MLPRegressor())
    f32 = MLPRegressor(hidden_layer_sizes=(4,), max_iter=5, random_state=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        f32.fit(p.astype(np.float32), p[:, 0].astype(np.float32))
        two = MLPRegressor(hidden_layer_sizes=(4,), max_iter=5, random_state=0).fit(p, p)
    with pytest.raises(ValueError, match="float64"):
        mlp_arrays_from_sklearn(f32)
    with pytest.raises(ValueError, match="one output"):
        mlp_arrays_from_sklearn(two)
    with pytest.raises(ValueError, match="whiten"):
        pca_arrays_from_sklearn(PCA(n_components=2, whiten=True).fit(np.random.default_rng(0).normal(size=(10, 3))))
    with pytest.raises(ValueError, match="golden_inputs: the MLP takes 2 inputs"):
        _export(tmp_path / "x", trained, golden_inputs=np.zeros((4, 3)))
    bad_pre = dict(pre, pca_components=pca.components_[:1], pca_explained_variance_ratio=np.ones(1) * 0.5)
    with pytest.raises(B.ShapeError, match="mlp_W0"):
        export_paper_model(tmp_path / "w", mlp, bad_pre, p[:3], {}, "0" * 64)
    with pytest.raises(ValueError, match="golden_inputs"):
        _export(tmp_path / "y", trained, golden_inputs=np.zeros(4))
    _export(tmp_path / "z", trained)
    with pytest.raises(FileExistsError):
        _export(tmp_path / "z", trained)
