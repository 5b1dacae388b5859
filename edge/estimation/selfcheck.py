"""The device's semantic self-check: does a bundle *decide* sensibly, not only consistently?

Hashes and golden vectors prove that a bundle is the one its author wrote and that
this device computes what the author's machine computed.  They say nothing about
what the bundle decides: a bundle whose material names were permuted, or whose
network output was negated, re-sealed with fresh hashes and golden vectors, passes
both.  Before a bundle becomes current the device therefore answers a few
*reference touches* with it and compares the answers with physics it knows itself:

(a) reference touch
    For a few reference solids of the device's own material table
    (:mod:`edge.physics.materials`: tempered glass, PMMA, AISI 304 steel - low,
    middle and high effusivity) a noise-free record is generated on the device by
    the forward model (:func:`edge.physics.forward.step_response`, thick object)
    and estimated with the bundle.  The default method must return e within
    :data:`E_TOL_REL`, k within :data:`DEFAULT_K_TOL_LN` (the library prior's
    spread) and the reference's own name; the paper method's network must return
    k within :data:`PAPER_K_TOL_LN` of the table's k.
(b) names and classes
    No duplicate names; every library entry whose name is in the device's table
    has the table's k, rho c and effusivity (:data:`PROPERTY_TOL_REL`) and its
    class.  A bundle may carry materials the device does not know (they are not
    checked), but not known names with other materials' properties.

A bundle without a material library (``lib_*``) cannot produce an estimate on
the device (the estimator refuses it: every touch would fail loudly), so it has
no answer to check and passes unchecked.  Everything here is NumPy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from edge.estimation.estimate import Estimator
from edge.physics.forward import step_response
from edge.physics.materials import load_materials

__all__ = ["REFERENCE_MATERIALS", "SemanticCheckError", "reference_records", "semantic_check"]

#: Reference solids (names in edge/physics/data/materials.csv): low, middle and high effusivity.
REFERENCE_MATERIALS = ("pmma", "tempered_glass", "aisi_304")
#: Heater power density of the reference touches (W/m^3): mid-range of the training levels.
REFERENCE_Q_V_W_m3 = 9.0e7
REFERENCE_DURATION_s = 1.95
REFERENCE_DT_s = 0.01
#: e from a noise-free record: the estimator's Duhamel inversion agrees with the forward model to ~0.1 %.
E_TOL_REL = 0.03
#: Default method's k: the library prior mixes neighbours of similar e (ln units; 0.5 ~ a factor 1.65).
DEFAULT_K_TOL_LN = 0.5
#: Paper network's k on a training-like record: generous (a factor 2.7) - it catches nonsense, not
#: a slightly worse fit, which is the deploy gate's job.
PAPER_K_TOL_LN = 1.0
#: Library entries against the device's table.
PROPERTY_TOL_REL = 1e-6


class SemanticCheckError(ValueError):
    """A bundle decides something the device knows to be wrong; the message is one line."""


@dataclass(frozen=True)
class ReferenceRecord:
    """A noise-free touch of a reference solid: what the device would have recorded."""

    name: str
    cls: str
    k_W_mK: float
    rho_c_J_m3K: float
    effusivity_W_s05_m2K: float
    t_s: np.ndarray
    dT_K: np.ndarray
    q_W_m2: np.ndarray


@lru_cache(maxsize=1)
def reference_records() -> tuple[ReferenceRecord, ...]:
    """The reference touches, generated once per process from the forward model."""
    lib = load_materials()
    t = np.arange(int(round(REFERENCE_DURATION_s / REFERENCE_DT_s)) + 1) * REFERENCE_DT_s
    out = []
    for name in REFERENCE_MATERIALS:
        m = lib.get(name)
        r = step_response(m.solid, REFERENCE_DURATION_s, t_s=t, back="infinite", thickness_m=None)
        out.append(ReferenceRecord(m.name, m.cls, m.k_W_mK, m.rho_c_J_m3K, m.solid.effusivity_W_s05_m2K,
                                   t, REFERENCE_Q_V_W_m3 * r.T_f_K, REFERENCE_Q_V_W_m3 * r.q_f_W_m2))
    return tuple(out)


def _g(x: float | None) -> str:
    return "no answer" if x is None else f"{x:.4g}"


def _check_library(arrays: Any) -> None:
    """(b): names unique; known names carry the device table's properties and class."""
    names = [str(n) for n in np.asarray(arrays["lib_names"]).ravel()]
    seen = set()
    for n in names:
        if n in seen:
            raise SemanticCheckError(f"library names {n!r} twice")
        seen.add(n)
    table = load_materials()
    e = np.asarray(arrays["lib_effusivity"], float)
    k = np.asarray(arrays["lib_k"], float)
    rc = np.asarray(arrays["lib_rho_c"], float)
    cls = [str(c) for c in np.asarray(arrays["lib_class"]).ravel()]
    for i, n in enumerate(names):
        if n not in table:
            continue
        m = table.get(n)
        want = {"k": m.k_W_mK, "rho c": m.rho_c_J_m3K, "effusivity": m.solid.effusivity_W_s05_m2K}
        got = {"k": k[i], "rho c": rc[i], "effusivity": e[i]}
        for q, v in want.items():
            if not abs(got[q] - v) <= PROPERTY_TOL_REL * abs(v):
                raise SemanticCheckError(f"library entry {n!r} has {q} {got[q]:.6g}, the device's material "
                                         f"table says {v:.6g}")
        # The bundle stores the class name or its report group (host.train writes the group).
        if cls[i] not in (m.cls, m.group):
            raise SemanticCheckError(f"library entry {n!r} has class {cls[i]!r}, the device's table says "
                                     f"{m.cls!r}")


def semantic_check(bundle: Any) -> None:
    """Refuse a bundle whose answers on the reference touches are wrong.

    Parameters
    ----------
    bundle : edge.model.bundle.Bundle
        A bundle that already passed the hash, schema and golden checks.

    Raises
    ------
    SemanticCheckError
        One line naming the first wrong answer.
    """
    arrays = bundle.arrays
    if "lib_names" not in arrays:
        # No library: the estimator cannot produce any answer with this bundle, so there is
        # nothing to check (and nothing a touch would report).
        return
    _check_library(arrays)
    try:
        est = Estimator(arrays, getattr(bundle, "sha256", ""))
    except (ValueError, KeyError) as exc:
        raise SemanticCheckError(f"the estimator cannot use the bundle: {exc}") from None
    lib_names = {str(n) for n in np.asarray(arrays["lib_names"]).ravel()}
    for ref in reference_records():
        r = est.estimate(ref.t_s, ref.dT_K, ref.q_W_m2, method="default", q_v_W_m3=REFERENCE_Q_V_W_m3)
        e = r.effusivity_W_s05_m2K
        if e is None or not abs(e / ref.effusivity_W_s05_m2K - 1) <= E_TOL_REL:
            raise SemanticCheckError(f"reference touch {ref.name}: e = {_g(e)} against {ref.effusivity_W_s05_m2K:.5g}")
        # A bundle trained on a subset library may not know the reference; its names are then
        # held to the device's table by _check_library alone.
        if ref.name in lib_names and r.material != ref.name:
            raise SemanticCheckError(f"reference touch {ref.name}: the bundle names it {r.material!r}")
        if r.k_W_mK is None or not abs(math.log(r.k_W_mK / ref.k_W_mK)) <= DEFAULT_K_TOL_LN:
            raise SemanticCheckError(f"reference touch {ref.name}: default k = {_g(r.k_W_mK)} against "
                                     f"{ref.k_W_mK:.4g}")
        if est.has_paper:
            p = est.estimate(ref.t_s, ref.dT_K, ref.q_W_m2, method="paper", q_v_W_m3=REFERENCE_Q_V_W_m3)
            if p.k_W_mK is None or not abs(math.log(p.k_W_mK / ref.k_W_mK)) <= PAPER_K_TOL_LN:
                raise SemanticCheckError(f"reference touch {ref.name}: the network's k = {_g(p.k_W_mK)} against "
                                         f"{ref.k_W_mK:.4g}")
