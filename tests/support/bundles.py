"""Shared builders for the bundle / model-store tests (small, valid bundles without sklearn)."""

from __future__ import annotations

import functools
import hashlib
import io
import json
from pathlib import Path

import numpy as np

from edge.estimation.mlp import MLP

N_FEATURES = 8
N_COMPONENTS = 2


def make_arrays(seed: int = 0, hidden=(100, 20)) -> dict[str, np.ndarray]:
    """A valid schema-v1 array set with a random tanh MLP."""
    rng = np.random.default_rng(seed)
    sizes = (N_COMPONENTS, *hidden, 1)
    ws = [rng.normal(scale=0.5, size=(a, b)) for a, b in zip(sizes[:-1], sizes[1:])]
    bs = [rng.normal(scale=0.1, size=b) for b in sizes[1:]]
    net = MLP(ws, bs, "tanh", "identity")
    arrays = {
        "feature_version": np.array(1, np.int64),
        "x_log_offset": np.zeros(N_FEATURES),
        "x_mean": rng.normal(size=N_FEATURES),
        "x_scale": rng.uniform(0.5, 2.0, size=N_FEATURES),
        "pca_mean": np.zeros(N_FEATURES),
        "pca_components": rng.normal(size=(N_COMPONENTS, N_FEATURES)),
        "pca_explained_variance_ratio": np.array([0.9, 0.06]),
        "y_transform": np.array(1, np.int64),
    }
    arrays.update(net.to_arrays())
    return arrays


def make_golden(arrays: dict, seed: int = 1, n: int = 16) -> dict[str, np.ndarray]:
    x = np.random.default_rng(seed).normal(size=(n, N_COMPONENTS))
    return {"mlp_inputs": x, "mlp_outputs": MLP.from_arrays(arrays).predict(x)}


def manifest_extra(version: str = "1.0") -> dict:
    return {
        "training_set_sha256": hashlib.sha256(b"training set").hexdigest(),
        "metrics": {"r2": 0.99, "mape": 0.05},
        "description": "test bundle",
        "model_version": version,
        "created_utc": "2024-01-01T00:00:00Z",
    }


def npz_bytes(arrays: dict, allow_pickle: bool = False) -> bytes:
    """A standard numpy npz (np.savez), optionally allowing object arrays for hostile files."""
    buf = io.BytesIO()
    np.savez(buf, allow_pickle=allow_pickle, **arrays)
    return buf.getvalue()


def write_raw_bundle(
    path: Path,
    arrays_bytes: bytes,
    golden_bytes: bytes,
    manifest_overrides: dict | None = None,
    manifest_text: bytes | None = None,
) -> Path:
    """Write the three files directly, with a manifest whose hashes match (unless overridden).

    Used to build hostile bundles the writer would refuse.
    """
    path.mkdir(parents=True, exist_ok=False)
    (path / "arrays.npz").write_bytes(arrays_bytes)
    (path / "golden.npz").write_bytes(golden_bytes)
    if manifest_text is None:
        m = {"schema_version": 1, **manifest_extra()}
        m["files"] = {
            "arrays.npz": {"sha256": hashlib.sha256(arrays_bytes).hexdigest(), "size": len(arrays_bytes)},
            "golden.npz": {"sha256": hashlib.sha256(golden_bytes).hexdigest(), "size": len(golden_bytes)},
        }
        m.update(manifest_overrides or {})
        manifest_text = json.dumps(m).encode()
    (path / "manifest.json").write_bytes(manifest_text)
    return path


def reseal(path: Path) -> None:
    """Recompute the manifest's file hashes after a test tampered with a file."""
    m = json.loads((path / "manifest.json").read_text())
    for name in ("arrays.npz", "golden.npz"):
        data = (path / name).read_bytes()
        m["files"][name] = {"sha256": hashlib.sha256(data).hexdigest(), "size": len(data)}
    (path / "manifest.json").write_text(json.dumps(m))


def broken_copy(src, dst: Path, how: str):
    """A self-consistent but wrong copy of the bundle at ``src``: fresh hashes and golden vectors.

    ``how``: ``"permuted_names"`` (the library's names rolled by one place: every material
    carries another's name) or ``"negated_output"`` (the network's last layer negated, so
    ln k -> -ln k).  Returns the written :class:`edge.model.bundle.Bundle`.
    """
    from edge.estimation.estimate import Estimator, pipeline_golden_check
    from edge.model import bundle as B

    src_b = B.load_bundle(src, pipeline_golden_check)
    arrays = {k: np.array(v) for k, v in src_b.arrays.items()}
    if how == "permuted_names":
        arrays["lib_names"] = np.roll(arrays["lib_names"], 1)
    elif how == "negated_output":
        last = int(arrays["mlp_n_layers"]) - 1
        arrays[f"mlp_W{last}"] = -arrays[f"mlp_W{last}"]
        arrays[f"mlp_b{last}"] = -arrays[f"mlp_b{last}"]
    else:
        raise ValueError(how)
    with np.load(Path(src) / "golden.npz") as z:
        golden = {k: z[k] for k in z.files}
    # Golden vectors recomputed from the tampered arrays: they agree with it, as a forger's would.
    golden["mlp_outputs"] = MLP.from_arrays(arrays).predict(golden["mlp_inputs"])
    if "pipeline_features" in golden:
        golden["pipeline_k"] = Estimator(arrays, "").paper_k(golden["pipeline_features"])[0]
    extra = {k: v for k, v in src_b.manifest.items() if k not in ("files", "schema_version")}
    extra["model_version"] = f"{src_b.model_version}-{how}"
    return B.write_bundle(dst, arrays, golden, extra, golden_check=pipeline_golden_check)


@functools.lru_cache(maxsize=None)
def shipped_small_heater_estimator():
    """The small-heater probe's estimator on the shipped bundle (its library is the prior), built once per process.

    Shared by the small-heater estimate tests; nothing in them writes into it.
    """
    from edge.estimation.estimate import Estimator, pipeline_golden_check
    from edge.estimation.probe_estimate import AxiEstimator
    from edge.model.bundle import load_bundle
    from thermotouch_models import DEFAULT_BUNDLE

    return AxiEstimator(Estimator.from_bundle(load_bundle(DEFAULT_BUNDLE, golden_check=pipeline_golden_check)),
                        "small-heater")
