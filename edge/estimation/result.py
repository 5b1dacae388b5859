"""The one answer of a touch: :class:`Estimate`, typed and immutable.

Every estimate path -- the device after a touch, ``thermotouch estimate`` on
an exported record, ``thermotouch calibrate`` re-measuring its references,
the demo and the benches -- ends in one :class:`Estimate`, made by
:func:`edge.estimation.seam.estimate_touch`.  Nothing changes it after it is
made: a step that adds something (the running decision's verdict, say)
builds a new one with :func:`dataclasses.replace`.

What it says, per quantity (effusivity e, conductivity k, diffusivity α):
the value and its standard uncertainty (absent -- None -- when the touch did
not give it), where it came from (:attr:`Estimate.determined_by`: ``"data"``,
``"prior"`` (the bundle's library given e), ``"calibration"`` or
``"thickness"``), the correlation of the ln errors where the method knows
it, the fit's normalised residual, the method and the parts of u(e), the
identities of the calibration and the model, flags from the one
:class:`edge.status.Flag` enum, and which object of the active set it names.
:meth:`Estimate.to_dict` is the JSON shape stored in the history and sent
over the wire.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Mapping

from edge.status import Flag

__all__ = ["Estimate", "QUANTITIES", "SOURCES", "RESULT_KEYS", "BLOCKERS", "unknown_recognition"]

#: The quantities an estimate reports, in order (keys of ``determined_by``).
QUANTITIES = ("e", "k", "alpha")
#: Where a quantity came from.
SOURCES = ("data", "prior", "calibration", "thickness")
#: The one blocker table: flags under which an estimate does not describe the record.  An e flagged so is
#: not taken as the answer (the calibrated chain's, :func:`edge.estimation.seam.chain_answer`) nor as a
#: running answer (every decision of :mod:`edge.estimation.running`).
BLOCKERS = frozenset({Flag.POOR_FIT, Flag.CONTACT_LOST, Flag.NO_CONTACT, Flag.NO_FIT, Flag.NOT_CONVERGED,
                      Flag.INSUFFICIENT_SIGNAL, Flag.SATURATED})
#: The recognition keys every answer carries (``class`` is :attr:`Estimate.cls`).
RECOGNITION_KEYS = ("object_set", "object", "object_posterior", "class", "class_posterior", "unknown_posterior",
                    "candidates")


def _num(x: Any) -> float | None:
    """A finite float or None (NaN, inf and None are 'not given')."""
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


#: Significant digits of a probability in :meth:`Estimate.to_dict` (a record must fit one 4-kB reply with
#: room for another; a posterior is not known to better than its inputs' few percent anyway).
P_DIGITS = 4


def _p(x: Any) -> float | None:
    """A probability as stored: finite, to P_DIGITS significant digits (None stays None)."""
    x = _num(x)
    return None if x is None else float(f"{x:.{P_DIGITS}g}")


def _plain(v: Any) -> Any:
    """JSON-safe copy of a details value: mappings, sequences, numbers (non-finite -> None), strings."""
    if isinstance(v, Mapping):
        return {str(k): _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, bool) or v is None or isinstance(v, str):
        return v
    if isinstance(v, int):
        return int(v)
    if isinstance(v, float):
        return _num(v)
    if hasattr(v, "item"):
        return _plain(v.item())
    return v


def _freeze(v: Any) -> Any:
    """Read-only view of a details value (mappings as MappingProxyType, lists as tuples)."""
    if isinstance(v, Mapping):
        return MappingProxyType({str(k): _freeze(x) for k, x in v.items()})
    if isinstance(v, (list, tuple)):
        return tuple(_freeze(x) for x in v)
    return v


def unknown_recognition(object_set: str | None = None) -> dict[str, Any]:
    """The recognition fields of an answer that names no object (no set, or no effusivity to name one by)."""
    return {"object_set": object_set, "object": "unknown", "object_posterior": None, "class": None,
            "class_posterior": None, "unknown_posterior": None, "candidates": []}


@dataclass(frozen=True)
class Estimate:
    """One touch's answer (SI units; ``*_u`` standard uncertainties, k = 1).

    Parameters
    ----------
    probe : str
        The probe head that took the touch.
    method : str
        What gave e: ``"default"``, ``"paper"`` (the 1-D methods), ``"axisym"`` (the small heater's fit),
        ``"sensor_chain"`` (the calibrated chain's e, k and α from the prior given it), ``"none"``.
    effusivity_W_s05_m2K, k_W_mK, alpha_m2_s : float or None
        The values (None: the touch did not give it).
    effusivity_W_s05_m2K_u, k_W_mK_u, alpha_m2_s_u : float or None
        Their standard uncertainties (None with the value).
    determined_by : mapping
        Quantity (``"e"``, ``"k"``, ``"alpha"``) -> ``"data"``, ``"prior"``, ``"calibration"`` or
        ``"thickness"``; only quantities that have a value.
    corr_ln : mapping
        Correlations of the ln errors the method knows: ``"k_alpha"``, ``"e_alpha"``.
    prior_reason : str or None
        Why k and α came from the prior (None: they did not).
    normalised_residual : float or None
        The fit's rms residual over the noise (1: the model describes the record to its noise).
    u_e_parts : mapping
        Relative parts of u(e) by source (fit, calibration, floor, contact, lateral, flux ...).
    calibration_sha256, model_sha256 : str or None
        The calibration that was applied (None: none) and the model bundle.
    flags : tuple of Flag
        Quality flags (the sequence's and the estimate's), each a :class:`edge.status.Flag`.
    material, material_confidence, material_candidates
        The library's nearest material by e, its confidence and the library's list.
    object_set, object, object_posterior, cls, class_posterior, unknown_posterior, candidates
        Recognition among the active object set (``object = "unknown"`` when it cannot say).
    details : mapping
        The method's own parts, JSON-able: ``fit``, ``sensor_chain``, ``default_method``, ``decision``
        ... (copied into :meth:`to_dict` under their names).
    series : mapping
        Arrays (the grid the method saw, its fit), not in :meth:`to_dict`.
    """

    probe: str
    method: str
    effusivity_W_s05_m2K: float | None = None
    effusivity_W_s05_m2K_u: float | None = None
    k_W_mK: float | None = None
    k_W_mK_u: float | None = None
    alpha_m2_s: float | None = None
    alpha_m2_s_u: float | None = None
    determined_by: Mapping[str, str] = field(default_factory=dict)
    corr_ln: Mapping[str, float] = field(default_factory=dict)
    prior_reason: str | None = None
    normalised_residual: float | None = None
    u_e_parts: Mapping[str, float] = field(default_factory=dict)
    calibration_sha256: str | None = None
    model_sha256: str | None = None
    flags: tuple[Flag, ...] = ()
    material: str | None = None
    material_confidence: float = 0.0
    material_candidates: tuple[tuple[str, float], ...] = ()
    object_set: str | None = None
    object: str = "unknown"
    object_posterior: float | None = None
    cls: str | None = None
    class_posterior: float | None = None
    unknown_posterior: float | None = None
    candidates: tuple[Mapping[str, Any], ...] = ()
    details: Mapping[str, Any] = field(default_factory=dict)
    #: The arrays behind it, not part of the JSON: ``grid_t_s``, ``grid_dT_K``, ``grid_q_W_m2`` (the
    #: conditioned heating phase) and, where the method has one, ``t_model_s``, ``fit_T_K`` (its model).
    series: Mapping[str, Any] = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        for name in ("effusivity_W_s05_m2K", "k_W_mK", "alpha_m2_s"):
            v, u = _num(getattr(self, name)), _num(getattr(self, name + "_u"))
            if v is None or u is None or u < 0:
                # A value without a finite u is not an answer: both absent.
                v = u = None
            set_(self, name, v)
            set_(self, name + "_u", u)
        flags = []
        for f in self.flags:
            f = Flag(f)   # ValueError for a word that is not a Flag
            if f not in flags:
                flags.append(f)
        set_(self, "flags", tuple(flags))
        have = {"e": self.effusivity_W_s05_m2K, "k": self.k_W_mK, "alpha": self.alpha_m2_s}
        det = {}
        for q, src in dict(self.determined_by).items():
            if q not in QUANTITIES:
                raise ValueError(f"determined_by: unknown quantity {q!r}; known: {QUANTITIES}")
            if src not in SOURCES:
                raise ValueError(f"determined_by[{q!r}]: unknown source {src!r}; known: {SOURCES}")
            if have[q] is not None:
                det[q] = src
        set_(self, "determined_by", MappingProxyType(det))
        set_(self, "corr_ln", MappingProxyType({k: float(v) for k, v in dict(self.corr_ln).items()
                                               if _num(v) is not None}))
        set_(self, "u_e_parts", MappingProxyType({k: float(v) for k, v in dict(self.u_e_parts).items()
                                                 if _num(v) is not None}))
        set_(self, "normalised_residual", _num(self.normalised_residual))
        set_(self, "material_confidence", float(self.material_confidence))
        set_(self, "material_candidates", tuple((str(n), float(c)) for n, c in self.material_candidates))
        set_(self, "candidates", tuple(MappingProxyType(dict(c)) for c in self.candidates))
        set_(self, "object", "unknown" if self.object is None else str(self.object))
        set_(self, "details", _freeze(dict(self.details)))
        set_(self, "series", MappingProxyType(dict(self.series)))

    # -- derived ---------------------------------------------------------------------------------
    @property
    def determined(self) -> tuple[str, ...]:
        """The quantities the touch itself determined (by its data, or its data and a stated thickness)."""
        return tuple(q for q in QUANTITIES if self.determined_by.get(q) in ("data", "thickness"))

    @property
    def from_prior(self) -> tuple[str, ...]:
        """The quantities that came from the library prior given e."""
        return tuple(q for q in QUANTITIES if self.determined_by.get(q) == "prior")

    @property
    def fit_T_K(self) -> Any:
        """The method's model temperature on :attr:`t_model_s` (None: the method has none)."""
        return self.series.get("fit_T_K")

    @property
    def t_model_s(self) -> Any:
        """The grid of :attr:`fit_T_K`."""
        return self.series.get("t_model_s")

    @property
    def ok(self) -> bool:
        """Whether the touch gave an effusivity."""
        return self.effusivity_W_s05_m2K is not None

    def recognition(self) -> dict[str, Any]:
        """The recognition fields as in :meth:`to_dict` (probabilities to :data:`P_DIGITS` significant digits)."""
        return {"object_set": self.object_set, "object": self.object, "object_posterior": _p(self.object_posterior),
                "class": self.cls, "class_posterior": _p(self.class_posterior),
                "unknown_posterior": _p(self.unknown_posterior),
                "candidates": [{**c, "posterior": _p(c.get("posterior"))} if "posterior" in c else dict(c)
                               for c in self.candidates]}

    def with_flags(self, *flags: Flag) -> "Estimate":
        """A copy with ``flags`` added (those already there are not repeated)."""
        from dataclasses import replace  # noqa: PLC0415 - keeps the module's namespace to the type

        return replace(self, flags=self.flags + tuple(flags))

    def to_dict(self) -> dict[str, Any]:
        """The JSON shape: the same keys on every path (None where the touch gave nothing)."""
        d: dict[str, Any] = {
            "effusivity_W_s05_m2K": self.effusivity_W_s05_m2K,
            "effusivity_W_s05_m2K_u": self.effusivity_W_s05_m2K_u,
            "k_W_mK": self.k_W_mK, "k_W_mK_u": self.k_W_mK_u,
            "alpha_m2_s": self.alpha_m2_s, "alpha_m2_s_u": self.alpha_m2_s_u,
            "material": self.material, "material_confidence": _p(self.material_confidence),
            "method": self.method, "probe": self.probe,
            "model_sha256": self.model_sha256, "calibration_sha256": self.calibration_sha256,
            "flags": [str(f) for f in self.flags],
            "determined": list(self.determined), "from_prior": list(self.from_prior),
            "determined_by": dict(self.determined_by), "prior_reason": self.prior_reason,
            "corr_k_alpha": self.corr_ln.get("k_alpha"), "corr_e_alpha": self.corr_ln.get("e_alpha"),
            "normalised_residual": self.normalised_residual, "u_e_parts": dict(self.u_e_parts),
            **self.recognition(),
        }
        for k, v in self.details.items():
            if k not in d:
                d[k] = _plain(v)
        return d


#: The keys of :meth:`Estimate.to_dict` every answer carries (``details`` add their own after these).
RESULT_KEYS = tuple(Estimate(probe="paper", method="none").to_dict())
