"""A probe's calibration: its sensor chain's parameters, their covariance, and how well it transfers.

ISSUE #10 §4.  The sensor-chain estimator (:mod:`edge.estimation.sensor_chain`)
needs three things the datasheet gets wrong on a real probe: the thermopile's
sensitivity (as ``flux_scale`` = nominal / true), the effective depth and
conductivity of the sensing layer between the thermopile and the object
(its rho c kept nominal: the conductivity moves its effusivity, which sets
how much heat the layer itself stores, the depth its delay), and the
thermocouple's bead lag.  A :class:`ProbeCalibration` holds them as the
parameter vector ``theta = (ln flux_scale, ln sensing_thickness_m,
tc_tau_s, ln sensing_k_W_mK)`` with a 4 x 4 covariance, so every measurement can carry their uncertainty; plus
``u_rel_floor``, the relative scatter of e that remained on the reference
touches after calibration (what the chain model does not describe: a floor
added to every measurement's u(e)).

An uncalibrated probe is :meth:`ProbeCalibration.nominal`: datasheet values
with the as-delivered spreads of :mod:`edge.physics.probe` as covariance,
``calibrated = False`` (measurements are flagged ``uncalibrated``).

On disk a calibration is one JSON object (:meth:`to_json`), versioned
(``format``, ``schema_version``) and checked on load field by field with
:mod:`edge.schema`; its identity is the SHA-256 of its canonical JSON
(:attr:`ProbeCalibration.sha256`), which a stored file repeats and which
measurements record.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field
from datetime import datetime, timezone
from typing import Any

import numpy as np

from edge.estimation.chain_estimate import DatasheetChain
from edge.estimation.sensor_chain import SensorChainCalibration, chain_theta, chain_with_theta
from edge.physics.geometry import PROBES
from edge.schema import Field, SchemaError, check_table

__all__ = ["CalibrationError", "PARAMETERS", "ProbeCalibration", "ReferenceFit", "FORMAT", "SCHEMA_VERSION",
           "FLUX_SCALE_BOUNDS", "COVARIANCE_PRIOR_FACTOR", "check_plausible", "parse_created_utc", "identifiability",
           "DETERMINED_SHRINK", "extrapolation_rates"]

FORMAT = "thermotouch-calibration"
SCHEMA_VERSION = 1
#: Names of the calibrated parameter vector theta, in order.
PARAMETERS = ("ln_flux_scale", "ln_sensing_thickness_m", "tc_tau_s", "ln_sensing_k_W_mK")
N_PARAMETERS = len(PARAMETERS)
#: Largest calibration file accepted (bytes): a calibration is a few kB.
MAX_BYTES = 65536
#: Plausible flux scale (true flux per unit of the datasheet reading).  The thermopile's datasheet
#: gives its sensitivity within +-5 % (1 sigma, edge.physics.probe.FLUX_SENSITIVITY_U_REL); 0.8-1.25
#: is more than 4 sigma either way (symmetric in ln: 1/0.8 = 1.25).  A calibration outside it does not
#: describe this sensor but a wrong reference, a wrong head or a hand-edited file (ISSUE #35 §2: a
#: x2 "calibration" turned glass into bismuth).
FLUX_SCALE_BOUNDS = (0.8, 1.25)
#: A calibration's covariance may be no wider than its prior (the datasheet spreads of
#: ProbeCalibration.nominal): the references can only narrow what the datasheet says.  The factor
#: allows the noise-bias correction's own sampling scatter, added to the fit's covariance (a few per
#: cent of a variance), and rounding.
COVARIANCE_PRIOR_FACTOR = 1.5
#: A parameter is determined by the references when they shrink its datasheet u to this fraction or less
#: (ISSUE #34 item 1); otherwise its prior settles it, and the report says which reference would help.
DETERMINED_SHRINK = 0.5
#: Correlations of theta beyond this are reported: the references trade the two off.
STRONG_CORRELATION = 0.8
#: Per parameter: the reference or touch that would determine it.
ADVICE = {
    "ln_flux_scale": "touch a certified metal block (aisi_304) and a polymer block (pmma): the sensitivity scales "
                     "every e alike, only materials of well-known e pin it",
    "ln_sensing_thickness_m": "touch a metal block (aisi_304): the layer's depth shows where the object draws the "
                              "most heat through it",
    "tc_tau_s": "touch a metal block firmly, or with the block off the probe's temperature: the bead lag shows on "
                "the fastest rises",
    "ln_sensing_k_W_mK": "touch an insulating foam (or record the probe in air before each touch): the layer's heat "
                         "capacity then shows apart from its resistance, and with it its conductivity",
}
#: A reference touch that got no answer from the calibration fitted without it counts, in the extrapolation
#: rate (:func:`extrapolation_rates`), as a miss of this (ln e): the model-form term then takes the
#: same span to grow by it.
UNANSWERED_MISS = 0.5
#: created_utc's format (as model manifests: the order of updates).
TIME_FORMAT = "%Y-%m-%dT%H:%M:%SZ"


class CalibrationError(ValueError):
    """A calibration that cannot be used; the message names the field at fault."""


@dataclass(frozen=True)
class ReferenceFit:
    """One reference material of a calibration and how the calibrated probe then read it."""

    name: str
    e_W_s05_m2K: float          # the library's value the calibration trusted
    u_rel_e: float              # its stated relative standard uncertainty
    n_touches: int
    rel_errors: tuple[float, ...]   # (e measured with the calibration) / e - 1, per touch

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "e_W_s05_m2K": self.e_W_s05_m2K, "u_rel_e": self.u_rel_e,
                "n_touches": self.n_touches, "rel_errors": list(self.rel_errors)}


_REF_FIELDS = {
    "name": Field("str", doc="library name", lo=1, hi=64),
    "e_W_s05_m2K": Field("float", doc="reference effusivity", lo=0.0, lo_open=True),
    "u_rel_e": Field("float", doc="its relative standard uncertainty", lo=0.0, hi=1.0),
    "n_touches": Field("int", doc="touches of it", lo=1, hi=10000),
    "rel_errors": Field("list_num", doc="calibrated e / reference e - 1 per touch", hi=10000),
}
_CHAIN_FIELDS = {
    "sensing_thickness_m": Field("float", lo=1e-6, hi=0.01),
    "k_W_mK": Field("float", lo=1e-3, hi=1e3),
    "alpha_m2_s": Field("float", lo=1e-9, hi=1e-3),
    "tc_tau_s": Field("float", lo=0.0, hi=10.0),
    "flux_scale": Field("float", lo=0.1, hi=10.0),
}
_FIELDS = {
    "format": Field("str", choices=(FORMAT,)),
    "schema_version": Field("int", choices=(SCHEMA_VERSION,)),
    "probe": Field("str", choices=tuple(PROBES)),
    "calibrated": Field("bool"),
    "created_utc": Field("str", hi=64),
    "chain": Field("table"),
    "parameters": Field("list_str", lo=4, hi=4),
    "covariance": Field("list"),
    "u_rel_floor": Field("float", lo=0.0, hi=1.0),
    "references": Field("list", hi=64),
    # Required, checked after the fields (so a bad field is named first): see from_json.
    "sha256": Field("sha256", default=None),
    # Optional (absent in files that predate them, so their sha256 is unchanged):
    "device_id": Field("str", default=None, lo=1, hi=64, doc="the device it was fitted for (INFO device_id)"),
    "forced": Field("bool", default=None, doc="written with --force although its self-check failed"),
    "self_check": Field("table", default=None, doc="leave-one-reference-out check of the fit"),
    "head_model": Field("table", default=None, doc="the head's own calibrated model (small heater: substrate)"),
}


@dataclass(frozen=True, eq=False)
class ProbeCalibration:
    """The sensor chain of one probe, with uncertainties.

    Attributes
    ----------
    probe : str
        Probe head (a name in :data:`edge.physics.geometry.PROBES`).
    chain : SensorChainCalibration
        Values the estimator uses.
    covariance : ndarray (4, 4)
        Covariance of theta = (ln flux_scale, ln sensing_thickness_m, tc_tau_s, ln sensing_k_W_mK).
    u_rel_floor : float
        Relative standard uncertainty added to every e (the scatter left on the references).
    calibrated : bool
        False for the datasheet probe (:meth:`nominal`).
    created_utc : str
    references : tuple of ReferenceFit
    """

    probe: str
    chain: SensorChainCalibration
    covariance: np.ndarray
    u_rel_floor: float = 0.0
    calibrated: bool = False
    created_utc: str = ""
    references: tuple[ReferenceFit, ...] = field(default_factory=tuple)
    #: The device it was fitted for (its INFO ``device_id``; None: not bound to one).
    device_id: str | None = None
    #: Written although its leave-one-out self-check failed (``calibrate --force``).
    forced: bool = False
    #: The leave-one-reference-out check (:mod:`edge.calibration.selfcheck`), as a JSON table.
    self_check: dict[str, Any] | None = None
    #: The probe head's own calibrated model parameters beyond the chain (small heater: the substrate's
    #: k and rho c, the fit's covariance and identifiability; :mod:`edge.calibration.axi`), as a JSON table.
    head_model: dict[str, Any] | None = None

    def __post_init__(self) -> None:
        if self.probe not in PROBES:
            raise CalibrationError(f"probe: unknown probe {self.probe!r}; known: {', '.join(PROBES)}")
        cov = np.array(self.covariance, dtype=np.float64)
        if cov.shape != (N_PARAMETERS, N_PARAMETERS) or not np.all(np.isfinite(cov)):
            raise CalibrationError(f"covariance: must be a finite {N_PARAMETERS} x {N_PARAMETERS} matrix")
        if not np.allclose(cov, cov.T, rtol=1e-9, atol=1e-300):
            raise CalibrationError("covariance: must be symmetric")
        if np.any(np.linalg.eigvalsh(0.5 * (cov + cov.T)) < -1e-12 * max(1e-300, float(np.max(np.abs(cov))))):
            raise CalibrationError("covariance: must be positive semi-definite")
        cov.flags.writeable = False
        object.__setattr__(self, "covariance", cov)
        if not (0.0 <= self.u_rel_floor <= 1.0 and math.isfinite(self.u_rel_floor)):
            raise CalibrationError(f"u_rel_floor: must be in [0, 1], got {self.u_rel_floor!r}")

    def __eq__(self, other: object) -> bool:
        # Two calibrations are the same when their files would be (the covariance is an array).
        return isinstance(other, ProbeCalibration) and other.sha256 == self.sha256

    def __hash__(self) -> int:
        return hash(self.sha256)

    @classmethod
    def nominal(cls, probe: str = "paper") -> "ProbeCalibration":
        """The uncalibrated probe: datasheet values, as-delivered spreads as covariance."""
        d = DatasheetChain(probe=probe)
        return cls(probe=probe, chain=d.chain, covariance=d.covariance, calibrated=False)

    @property
    def theta(self) -> np.ndarray:
        """(ln flux_scale, ln sensing_thickness_m, tc_tau_s, ln sensing_k_W_mK)."""
        return chain_theta(self.chain)

    def chain_at(self, theta) -> SensorChainCalibration:
        """The chain with parameters ``theta`` (a bead lag below 0 is 0: it cannot lead; rho c is kept)."""
        return chain_with_theta(self.chain, theta)

    @property
    def created_time(self) -> datetime:
        """:attr:`created_utc` as an aware UTC datetime (the order of calibrations; CalibrationError if none)."""
        return parse_created_utc(self.created_utc)

    @property
    def u_theta(self) -> np.ndarray:
        """Standard uncertainties of theta."""
        return np.sqrt(np.diag(self.covariance))

    def u_of(self, parameter: str) -> float:
        """Standard uncertainty of one parameter of theta, by its name in :data:`PARAMETERS`."""
        try:
            i = PARAMETERS.index(parameter)
        except ValueError:
            raise KeyError(f"unknown parameter {parameter!r}; known: {', '.join(PARAMETERS)}") from None
        return float(math.sqrt(max(float(self.covariance[i, i]), 0.0)))

    @property
    def flux_scale(self) -> float:
        """True flux per unit of the flux sensor's datasheet reading."""
        return float(self.chain.flux_scale)

    @property
    def flux_u_rel(self) -> float:
        """Relative standard uncertainty of :attr:`flux_scale` (u of ``ln_flux_scale``)."""
        return self.u_of("ln_flux_scale")

    def model_form_u_rel(self, e_W_s05_m2K: float) -> float:
        """The calibration's model-form term of u(e)/e at effusivity ``e``: its floor, and beyond its references
        the extrapolation the leave-one-out check measured.

        The references pin the chain where they lie; a solid below the lowest (a wood, a foam) or above
        the highest (copper) leans on the chain's layer terms the references could not separate (the
        sensitivity, the layer's depth and k trade off).  How far that carries is what the self-check
        saw when it left the lowest (highest) reference out and re-measured it from the others: its
        rms relative miss over the ln-e distance it was extrapolated is the rate, per unit of ln e, at
        which the model-form term grows outside the references (:func:`extrapolation_rates`).  Within
        the references' span it is the floor alone.  Never below the floor; 0 only for a calibration
        without a self-check whose references all re-measured exactly.
        """
        u = float(self.u_rel_floor)
        rates = extrapolation_rates(self)
        if rates is None or not (e_W_s05_m2K > 0 and math.isfinite(e_W_s05_m2K)):
            return u
        (e_lo, r_lo), (e_hi, r_hi) = rates
        ext = r_lo * max(0.0, math.log(e_lo / e_W_s05_m2K)) + r_hi * max(0.0, math.log(e_W_s05_m2K / e_hi))
        return float(math.hypot(u, ext))

    # -- storage ---------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        c = self.chain
        return {
            "format": FORMAT, "schema_version": SCHEMA_VERSION, "probe": self.probe,
            "calibrated": bool(self.calibrated), "created_utc": self.created_utc,
            "chain": {"sensing_thickness_m": c.sensing_thickness_m, "k_W_mK": c.k_W_mK,
                      "alpha_m2_s": c.alpha_m2_s, "tc_tau_s": c.tc_tau_s, "flux_scale": c.flux_scale},
            "parameters": list(PARAMETERS),
            "covariance": [[float(x) for x in row] for row in self.covariance],
            "u_rel_floor": float(self.u_rel_floor),
            "references": [r.to_dict() for r in self.references],
        } | ({} if self.device_id is None else {"device_id": self.device_id}) \
          | ({"forced": True} if self.forced else {}) \
          | ({} if self.self_check is None else {"self_check": self.self_check}) \
          | ({} if self.head_model is None else {"head_model": self.head_model})

    @property
    def sha256(self) -> str:
        """Identity: SHA-256 of the canonical JSON of :meth:`to_dict`."""
        return hashlib.sha256(_canonical(self.to_dict())).hexdigest()

    def to_json(self) -> str:
        """The file's text: the fields and their ``sha256``."""
        d = self.to_dict()
        d["sha256"] = self.sha256
        return json.dumps(d, indent=1, sort_keys=True) + "\n"

    def to_json_compact(self) -> str:
        """The same content as :meth:`to_json` without whitespace (what travels over the link)."""
        d = self.to_dict()
        d["sha256"] = self.sha256
        return json.dumps(d, sort_keys=True, separators=(",", ":"))

    @classmethod
    def from_json(cls, data: bytes | str) -> "ProbeCalibration":
        """Parse and check a calibration file's content. Raises :class:`CalibrationError`."""
        if isinstance(data, str):
            data = data.encode("utf-8")
        if len(data) > MAX_BYTES:
            raise CalibrationError(f"too large ({len(data)} bytes; a calibration is at most {MAX_BYTES})")
        try:
            d = json.loads(data.decode("utf-8-sig"))
        except RecursionError:
            raise CalibrationError("not a calibration (nested too deeply)") from None
        except UnicodeDecodeError as exc:
            raise CalibrationError(f"not UTF-8 text (byte {exc.start})") from None
        except json.JSONDecodeError as exc:
            raise CalibrationError(f"not JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})") from None
        try:
            top = check_table(d, _FIELDS)
            chain = check_table(top["chain"], _CHAIN_FIELDS, "chain")
            if tuple(top["parameters"]) != PARAMETERS:
                raise SchemaError("parameters", f"must be {list(PARAMETERS)}")
            refs = []
            for i, r in enumerate(top["references"]):
                rr = check_table(r, _REF_FIELDS, f"references[{i}]")
                if any(x is None for x in rr["rel_errors"]):
                    raise SchemaError(f"references[{i}].rel_errors", "must be numbers")
                refs.append(ReferenceFit(rr["name"], rr["e_W_s05_m2K"], rr["u_rel_e"], rr["n_touches"],
                                         tuple(float(x) for x in rr["rel_errors"])))
        except SchemaError as exc:
            raise CalibrationError(str(exc)) from None
        cov = top["covariance"]
        n = N_PARAMETERS
        if not (isinstance(cov, list) and len(cov) == n and all(isinstance(r, list) and len(r) == n for r in cov)
                and all(isinstance(x, (int, float)) and not isinstance(x, bool) for r in cov for x in r)):
            raise CalibrationError(f"covariance: must be a {n} x {n} list of numbers")
        try:
            cal = cls(probe=top["probe"], chain=SensorChainCalibration(**chain), covariance=np.array(cov, float),
                      u_rel_floor=top["u_rel_floor"], calibrated=top["calibrated"],
                      created_utc=top["created_utc"], references=tuple(refs), device_id=top.get("device_id"),
                      forced=bool(top.get("forced")), self_check=top.get("self_check"),
                      head_model=top.get("head_model"))
        except CalibrationError:
            raise
        except ValueError as exc:
            raise CalibrationError(f"chain: {exc}") from None
        if top.get("sha256") is None:
            # A file is only trusted with its checksum (ISSUE #34: one whose sha256 line was deleted by
            # hand installed); a caller that builds one in memory has the object, not a file.
            raise CalibrationError("sha256: missing (a calibration file carries the SHA-256 of its content; "
                                   "the file was edited or is not a calibration)")
        if top["sha256"] != cal.sha256:
            raise CalibrationError("sha256: does not match the content (the file was changed or damaged)")
        if cal.calibrated:
            check_plausible(cal)
        return cal


def parse_created_utc(text: str) -> datetime:
    """``created_utc`` as an aware datetime: YYYY-MM-DDTHH:MM:SSZ (what calibrate writes) or ISO 8601 at UTC.

    Raises :class:`CalibrationError` for anything else (a calibration must be ordered against another).
    """
    try:
        return datetime.strptime(str(text), TIME_FORMAT).replace(tzinfo=timezone.utc)
    except ValueError:
        pass
    try:
        t = datetime.fromisoformat(str(text))
    except ValueError:
        t = None
    if t is None or t.utcoffset() is None or t.utcoffset().total_seconds() != 0:
        raise CalibrationError(f"created_utc: {text!r} is not YYYY-MM-DDTHH:MM:SSZ (cannot order it)")
    return t.astimezone(timezone.utc)


def check_plausible(cal: ProbeCalibration) -> None:
    """Refuse a calibration the probe's physics cannot have produced (ISSUE #35 §2); the message says why.

    Checked: the flux scale within :data:`FLUX_SCALE_BOUNDS` (the sensor's datasheet tolerance),
    every variance of theta no wider than the datasheet prior's (x :data:`COVARIANCE_PRIOR_FACTOR`),
    the floor finite in [0, 1] (the constructor), and ``created_utc`` a time that can be ordered.
    """
    lo, hi = FLUX_SCALE_BOUNDS
    f = cal.flux_scale
    if not (lo <= f <= hi):
        raise CalibrationError(f"chain.flux_scale: {f:g} is outside the sensor's datasheet tolerance "
                               f"[{lo:g}, {hi:g}]; not a calibration of this sensor")
    prior = np.diag(ProbeCalibration.nominal(cal.probe).covariance)
    var = np.diag(cal.covariance)
    for name, v, v0 in zip(PARAMETERS, var, prior):
        if v > COVARIANCE_PRIOR_FACTOR * v0 + 1e-300:
            raise CalibrationError(f"covariance: {name}'s variance {v:.3g} is wider than its datasheet prior "
                                   f"{v0:.3g}; a calibration can only narrow it")
    parse_created_utc(cal.created_utc)


def extrapolation_rates(cal: "ProbeCalibration") -> tuple[tuple[float, float], tuple[float, float]] | None:
    """((e_lowest, rate below it), (e_highest, rate above it)) from the self-check's leave-one-out misses.

    The rate at an end is the rms of ln(e_remeasured / e_ref) over the end reference's touches (each
    re-measured by the calibration fitted without that reference), over ln of the ratio to the next
    reference's e (how far the held-out calibration extrapolated).  A touch that got no answer counts
    as a miss of :data:`UNANSWERED_MISS`.  None without a self-check of at least two references.
    """
    sc = cal.self_check or {}
    by: dict[str, list[float]] = {}
    e_of: dict[str, float] = {}
    for m in sc.get("misses") or ():
        try:
            name, e_ref = str(m["name"]), float(m["e_ref_W_s05_m2K"])
        except (KeyError, TypeError, ValueError):
            continue
        rel = m.get("rel_miss")
        miss = UNANSWERED_MISS if rel is None or not (rel > -1.0) else abs(math.log1p(float(rel)))
        by.setdefault(name, []).append(min(miss, UNANSWERED_MISS))
        e_of[name] = e_ref
    if len(e_of) < 2 or not all(v > 0 for v in e_of.values()):
        return None
    order = sorted(e_of, key=e_of.get)

    def rate(end: str, nxt: str) -> float:
        d = abs(math.log(e_of[nxt] / e_of[end]))
        rms = math.sqrt(sum(x * x for x in by[end]) / len(by[end]))
        return rms / d if d > 0 else 0.0
    return (e_of[order[0]], rate(order[0], order[1])), (e_of[order[-1]], rate(order[-1], order[-2]))


def _canonical(d: dict[str, Any]) -> bytes:
    return json.dumps(d, sort_keys=True, separators=(",", ":")).encode("utf-8")


def identifiability(cal: ProbeCalibration) -> dict[str, Any]:
    """What the references determined of theta, their correlations, and which reference would determine the rest.

    A parameter is determined when the calibration's u is at most :data:`DETERMINED_SHRINK` of the
    datasheet's (:meth:`ProbeCalibration.nominal`); otherwise the datasheet prior settled it and
    ``advice`` names the reference that would pin it (:data:`ADVICE`).  ``correlations``: the
    off-diagonal correlations of theta; ``traded_off``: the pairs beyond :data:`STRONG_CORRELATION`
    (the references trade one against the other: the issue's sensitivity against layer k).
    """
    prior = ProbeCalibration.nominal(cal.probe).u_theta
    u = cal.u_theta
    shrink = {n: float(a / b) if b > 0 else 1.0 for n, a, b in zip(PARAMETERS, u, prior)}
    det = [n for n in PARAMETERS if shrink[n] <= DETERMINED_SHRINK]
    uu = np.outer(u, u)
    corr = np.divide(cal.covariance, uu, out=np.zeros_like(cal.covariance), where=uu > 0)
    pairs = {f"{PARAMETERS[i]}~{PARAMETERS[j]}": float(corr[i, j])
             for i in range(len(PARAMETERS)) for j in range(i + 1, len(PARAMETERS))}
    return {"determined": det, "not_determined": [n for n in PARAMETERS if n not in det],
            "u_over_prior": shrink, "correlations": pairs,
            "traded_off": [k for k, c in pairs.items() if abs(c) >= STRONG_CORRELATION],
            "advice": list(dict.fromkeys(ADVICE[n] for n in PARAMETERS if n not in det))}
