"""Training sets: the forward model for every material x power level.

The paper's set (section 3.2): every library material at 21 heater power
densities from 4.0e7 to 1.4e8 W/m^3 for 1.95 s.  The model is linear in q_v,
so each material is simulated once (edge.physics.forward, default scheme) and scaled
to every level.  Each series is then observed as the instruments observe it
(edge.measure.instrument: own sampling rate, noise, ADC quantisation, flux range) and
resampled onto the model's 0.01-s grid by cubic spline before features are
taken - the same path a real measurement follows on the device.  Optional
noisy copies augment the clean series.  Deterministic for a seed; cached on
disk (``$THERMOTOUCH_CACHE`` or ``~/.cache/thermotouch``) under a hash of
every input, including the library's content and the feature version.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from edge.estimation.features import FEATURE_VERSION, paper_features
from edge.physics.forward import step_response
from edge.measure.instrument import INSTRUMENTS
from edge.physics.probe import STACKS
from edge.physics.solids import Solid
from edge.estimation.spline import resampling_operator
from edge.physics.materials import MaterialLibrary

PAPER_LEVELS_W_m3 = tuple(np.round(np.arange(4.0e7, 1.4e8 + 1.0, 5e6)).tolist())
#: Bump when the generation procedure changes.  2: noisy copies resampled by a per-call operator
#: (_Resampler), independent of the process's resampling cache - see _Resampler.
CODE_VERSION = 2


@dataclass(frozen=True)
class DatasetSpec:
    """Everything that determines a training set."""

    levels_W_m3: tuple = PAPER_LEVELS_W_m3
    duration_s: float = 1.95
    dt_s: float = 0.01
    back: str = "infinite"
    thickness_m: float | None = None
    stack: str = "0.42"
    instrument: str | None = "mcp9600"
    noisy_copies: int = 2
    seed: int = 20240108
    exclude: tuple = field(default_factory=tuple)


@dataclass
class Dataset:
    features: np.ndarray  # (N, 8)
    k_W_mK: np.ndarray
    rho_c_J_m3K: np.ndarray
    q_v_W_m3: np.ndarray
    material_index: np.ndarray
    noisy: np.ndarray  # bool: an augmented copy
    names: list
    sha256: str


class _Resampler:
    """Cubic-spline resampling onto the model grid, with the same arithmetic for every series.

    :func:`edge.estimation.spline.resample` evaluates the spline directly the
    first time a process meets a pair of time bases and as ``W @ y`` with a
    cached operator afterwards.  The two agree only to rounding (~1e-16
    relative), and a few features (u2, u7: differences of nearly equal numbers
    near the log floor) turn that into changes of up to 60 %, which the network
    fit amplifies into different weights.  A training set built through it
    therefore depended on what the process had resampled before (a full retrain
    after a quick one in the same process gave other arrays than a fresh
    process: ``python bench/gate_bench.py``).  Here each time base gets its own
    operator, built on first use in this call, and every series is ``W @ y``.
    """

    def __init__(self, t_new_s: np.ndarray) -> None:
        self.t_new_s = t_new_s
        self._ops: dict = {}

    def __call__(self, t_s: np.ndarray, y: np.ndarray) -> np.ndarray:
        key = (t_s.size, t_s.tobytes())
        W = self._ops.get(key)
        if W is None:
            W = self._ops[key] = resampling_operator(t_s, self.t_new_s)
        return W @ y


def _cache_dir() -> Path:
    return Path(os.environ.get("THERMOTOUCH_CACHE", Path.home() / ".cache" / "thermotouch"))


def spec_key(spec: DatasetSpec, lib: MaterialLibrary) -> str:
    """Hash of the spec, the library's content and the code versions."""
    h = hashlib.sha256()
    h.update(json.dumps(asdict(spec), sort_keys=True, default=list).encode())
    for m in lib:
        h.update(f"{m.name},{m.k_W_mK!r},{m.rho_kg_m3!r},{m.c_J_kgK!r};".encode())
    h.update(f"features={FEATURE_VERSION};code={CODE_VERSION}".encode())
    if spec.instrument:
        h.update(repr(INSTRUMENTS[spec.instrument]).encode())  # noise/ADC model is an input too
    return h.hexdigest()


def generate(spec: DatasetSpec, lib: MaterialLibrary, *, cache: bool = True, progress=None) -> Dataset:
    """Build (or load from the cache) the training set for ``spec``."""
    key = spec_key(spec, lib)
    path = _cache_dir() / f"dataset-{key[:24]}.npz"
    names = [m.name for m in lib if m.name not in spec.exclude]
    if cache and path.exists():
        try:
            with np.load(path, allow_pickle=False) as z:
                return Dataset(z["features"], z["k"], z["rho_c"], z["q_v"], z["material_index"], z["noisy"],
                               names, key)
        except (OSError, ValueError, KeyError):
            pass  # a damaged cache entry is rebuilt
    rng = np.random.default_rng(spec.seed)
    t = np.arange(int(round(spec.duration_s / spec.dt_s)) + 1) * spec.dt_s
    levels = np.asarray(spec.levels_W_m3, float)
    inst = INSTRUMENTS[spec.instrument] if spec.instrument else None
    resample = _Resampler(t)
    feats, ks, rcs, qvs, idx, noisy = [], [], [], [], [], []
    mats = [m for m in lib if m.name not in spec.exclude]
    for i, m in enumerate(mats):
        unit = step_response(Solid(m.k_W_mK, m.rho_kg_m3, m.c_J_kgK), spec.duration_s, t_s=t,
                             back=spec.back, thickness_m=spec.thickness_m, stack=STACKS[spec.stack])
        T = np.outer(levels, unit.T_f_K)
        q = np.outer(levels, unit.q_f_W_m2)
        batches = [(T, q, False)]
        for _ in range(spec.noisy_copies if inst else 0):
            Tn = np.empty_like(T)
            qn = np.empty_like(q)
            for j in range(levels.size):
                tT, Tm, tq, qm = inst.sample(t, T[j], q[j], rng, t0_offset_K=rng.uniform(0, inst.T_lsb_K))
                Tn[j] = resample(tT, Tm)
                qn[j] = resample(tq, qm)
            batches.append((Tn, qn, True))
        for TT, qq, is_noisy in batches:
            feats.append(paper_features(t, qq, TT))
            ks.append(np.full(levels.size, m.k_W_mK))
            rcs.append(np.full(levels.size, m.rho_c_J_m3K))
            qvs.append(levels)
            idx.append(np.full(levels.size, i))
            noisy.append(np.full(levels.size, is_noisy))
        if progress:
            progress(i + 1, len(mats))
    ds = Dataset(np.vstack(feats), np.concatenate(ks), np.concatenate(rcs), np.concatenate(qvs),
                 np.concatenate(idx), np.concatenate(noisy), names, key)
    if cache:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp.npz")
        np.savez(tmp, features=ds.features, k=ds.k_W_mK, rho_c=ds.rho_c_J_m3K, q_v=ds.q_v_W_m3,
                 material_index=ds.material_index, noisy=ds.noisy)
        os.replace(tmp, path)
    return ds
