"""An object set and recognising which of its objects a touch was (open set, calibrated).

A robot touches a handful of known things; :class:`ObjectSet` holds them
(:class:`~edge.recognition.objects.KnownObject`) and answers "which of them,
or none?" for a measured e with its uncertainty -- and, when a small-heater
probe also measures k and α, with all three.

Model
-----
Each object i is a Gaussian in ln e -- and, when a probe measures the
diffusivity too (the small-heater probe), jointly in (ln e, ln α) -- with
covariance

    T * (C_meas' + diag(spread_i^2 + calibration_ln^2, spread_i^2))

about what the object *reads* on this probe at this contact time: its ln e plus the probe's
fitted bias ``bias_ln + bias_slope (ln e_i - ln e_ref)`` (0 unless fitted: a calibrated paper
probe reads woods and polymers 4-11 % high at 1 s, ISSUE #37), where
``C_meas`` is the measurement's covariance of (ln e, ln α) (their correlation
included: a short touch fixes e = k / sqrt(α) much better than α, and the two
errors are correlated) and ``T`` is the set's *temperature*:
one scale on every variance, fitted on the host on held-out simulated
touches (host/recognition.py) so that a posterior of 0.9 is right about 90 %
of the time. ``C_meas'`` is ``C_meas`` with the variance of ln e scaled by ``u_var_scale`` k:
a set calibrated with T = 1 and k fitted instead scales only what the probe states, leaving
the objects' specimen spread (a property of the objects, not of the probe) as the user gave it
(ISSUE #37: T < 1 at 1 s narrowed the 5 % spread to 4.4 %, and the touches between two woods
0.05 apart in ln e were named at 0.46 and right 21 % of the time); k = 1 (default): as stated.
With ``u_shrink`` b < 1 the u in object j's likelihood is ``u_typ_j^(1-b) u^b``, the stated u shrunk
toward the u a touch of that object typically states (a curve in ln e, ``u_typ_ln0/1/2``): the stated
u's touch-to-touch variation is partly noise (ISSUE #37), so k scales ``k u_typ_j^(2(1-b)) u^(2b)``.
With ``outlier_weight`` ε > 0 each object's likelihood is a two-component mixture,
``(1 - ε) N(core) + ε N(core with σ_out² added to the variance of ln e)`` (``outlier_ln`` σ_out,
fitted per contact time beside T, host.recognition.fit_outlier): a short touch's estimator
failures (foam read 2x, aluminium 0.4x, ISSUE #37) sit in the broad component instead of
pulling T up for every touch; ε = 0 is the Gaussian alone, bit for bit.  The open-set test
stays on the core Gaussian (its z_crit is fitted for the in-set acceptance whatever the tail).
The specimen spread is read as independent lognormal spreads of
e and α. (ln e, ln α) carries everything a touch measures: k = e sqrt(α)
adds nothing. A measured
α's stated u enters as ``u (1 + a u)`` (``alpha_u_growth``, fitted on the
host like T: the fit's linearised u understates the scatter of a poorly
determined α). An object
given by e alone gets, for a measured α, a broad term (standard deviation
:data:`BROAD_LN`, centred on the measurement): the measurement neither
confirms nor refutes it.

Open set
--------
The answer is ``"unknown"`` when no object passes a test on its
standardised distance: the chi-square p-value of the object's distance
(1 degree of freedom per measured property the object has; with e alone,
``p < p_crit`` is ``|z| > z_crit``) is below ``p_crit = 2 (1 - Φ(z_crit))`` for
every object -- not a threshold on the argmax posterior, which is near 1 for
the nearest object however far it is.  With ``unknown_min_odds`` r > 0 (a
calibrated set's 1, host.recognition.calibrate) the background below must also hold
at least r times the most probable object's posterior of the open-set mixture: a
touch the test rejects but the posterior still gives to an object is answered with
that object (r = 1: "unknown" only when it is the most probable hypothesis).  The
test alone answered in-set touches from the spread's tail "unknown" at a confidence
(the background's mass) of 0.16-0.42, wrong every time (ISSUE #37).  The design
rates below are the test's alone (a lower bound on the acceptance). ``z_crit`` is chosen on the host so that
a target share of touches of in-set objects (99 %; issue #12 asks for at
least 95 %) is accepted (host/recognition.IN_SET_ACCEPTANCE_GOAL, acceptance_target). :meth:`ObjectSet.acceptance_probability`
gives the test's design rates: the share of an object's touches it accepts
(1 - false reject) and of an outside object's (false accept) -- an outside
object whose e lies within an in-set object's spread is accepted by any
e-only test, and the design rate says how often.

"unknown" also gets posterior mass, as a background hypothesis: prior
probability ``prior_unknown`` (each object gets ``(1 - prior_unknown) / n``)
and a flat density over ln e across the probe's range (:data:`UNKNOWN_LN_E_SPAN`;
broad terms for a measured k or α). It is near ``prior_unknown``-small beside a
good match and takes over far from every object; the *answer* is still set
by the test above, so reported masses stay honest where the two disagree
(near the critical distance).

Class posteriors are sums of the object posteriors over each class.

The built-in library set (:meth:`ObjectSet.from_library`) carries
:data:`LIBRARY_CALIBRATION`, fitted the same way on simulated touches of every
library material (bench/tactile_bench.py), so its posteriors are calibrated
too; a user set carries its own fit as ``#@`` directives.
"""

from __future__ import annotations

import csv
import io
import math
from collections import Counter
from dataclasses import dataclass
from typing import Iterable, Mapping

import numpy as np

from edge.physics.materials import load_materials
from edge.recognition.classify import Recognition, check_touch, classify_rows
from edge.recognition.objects import (BIAS_REF_E_W_s05_m2K, CONTACT_DIRECTIVES, DEFAULT_OUTLIER_LN,
                                      DEFAULT_PRIOR_UNKNOWN,
                                      DEFAULT_SPREAD_REL, DEFAULT_Z_CRIT,
                                      DIRECTIVES, UNKNOWN, KnownObject, contact_key, parse_csv)
from edge.recognition.touch import BROAD_LN, DEFAULT_ALPHA_U_GROWTH, effective_u_ln_alpha, measured_alpha
from edge.schema import check_keys, check_value

__all__ = ["LIBRARY_CALIBRATION", "Recognition", "ConfusionPair", "Confusion", "ObjectSet"]

#: Calibration of the built-in library set (:meth:`ObjectSet.from_library`): fitted by
#: ``python bench/tactile_bench.py`` (host.recognition.calibrate on simulated precision-board touches
#: of every library material, 0.5-2 s contacts, 5 % spread); reported there with its reliability table.
LIBRARY_CALIBRATION = {"temperature": 1.03, "z_crit": 1.96}


def _contact_table(table: Mapping[float, Mapping[str, float]] | None) -> dict[float, dict[str, float]]:
    """A per-contact-time calibration table, checked and sorted by contact time."""
    out: dict[float, dict[str, float]] = {}
    for t, entry in sorted((table or {}).items()):
        t = float(t)
        if not (math.isfinite(t) and t > 0):
            raise ValueError(f"contact_calibration: contact time must be a positive number of seconds, got {t!r}")
        check_keys(dict(entry), {k: DIRECTIVES[k] for k in CONTACT_DIRECTIVES})
        out[t] = {k: check_value(DIRECTIVES[k], float(v), f"{k}@{t:g}s") for k, v in entry.items()}
    return out


@dataclass(frozen=True)
class ConfusionPair:
    """Two objects whose effusivities differ by less than ``threshold_ln`` (ln units)."""

    a: str
    b: str
    delta_ln_e: float
    threshold_ln: float


@dataclass(frozen=True)
class Confusion:
    """Pairs e alone cannot separate, and the best accuracy any rule could reach on e alone."""

    u_ln_e: float
    pairs: tuple[ConfusionPair, ...]
    #: Bayes-optimal top-1 object accuracy (equal priors, e alone, stated variances).
    bayes_accuracy: float
    #: Bayes-optimal class accuracy.
    bayes_class_accuracy: float

    def to_dict(self) -> dict:
        return {
            "u_ln_e": self.u_ln_e,
            "pairs": [[p.a, p.b, p.delta_ln_e, p.threshold_ln] for p in self.pairs],
            "bayes_accuracy": self.bayes_accuracy,
            "bayes_class_accuracy": self.bayes_class_accuracy,
        }


class ObjectSet:
    """An ordered set of :class:`KnownObject` with unique names, and its fitted calibration.

    Parameters
    ----------
    objects : iterable of KnownObject
    temperature : float
        Scale on every variance (1: the stated uncertainties as they are).
    z_crit : float
        Critical standardised distance of the open-set test.
    calibration_ln : float
        Extra systematic standard deviation of ln e (a probe calibration term).
    prior_unknown : float
        Prior probability that a touched object is none of these.
    alpha_u_growth : float
        A measured α's uncertainty is used as ``u (1 + a u)`` (see :func:`effective_u_ln_alpha`).
    bias_ln, bias_slope : float
        The probe's bias of ln e at this contact time, ``bias_ln + bias_slope (ln e - ln e_ref)``
        (``e_ref`` :data:`~edge.recognition.objects.BIAS_REF_E_W_s05_m2K`): every object is expected
        to *read* its ln e plus that (``ln_e``; its own e is ``ln_e_nominal``).  Fitted on the host on
        touches of probes other than the one it is used with (host.recognition.fit_bias, ISSUE #37:
        at 1 s the calibrated paper probe reads woods and polymers 5-10 % high, metals low).
    poor_fit_ln : float
        Standard deviation of ln e (before the temperature) with which a touch whose calibrated
        chain fitted poorly -- its e withheld from the answer -- still names an object from the
        chain's e (:func:`~edge.recognition.fields.recognition_fields`); 0: it names none.
    outlier_weight, outlier_ln : float
        Weight ε and extra sd of ln e σ_out of the likelihood's outlier component (module
        docstring); ε = 0 (default): the Gaussian alone.
    u_var_scale : float
        Scale k on the measurement's variance of ln e alone (module docstring); 1 (default): the
        stated u.  ``poor_fit_ln`` is scaled with it as a stated u, but not shrunk by ``u_shrink``: it is
        the set's fitted width, not a touch's noisy estimate of its own.
    u_shrink, u_typ_ln0, u_typ_ln1, u_typ_ln2 : float
        The likelihood of object j uses ``u_typ_j^(1-b) u^b`` for a touch stating u (:meth:`likelihood_u`):
        b ``u_shrink`` (1, default: the stated u), ``u_typ_j`` the u a touch of object j typically states,
        ``exp(a0 + a1 x + a2 x²)`` at x = ln(e_j / e_ref) (fitted on the host, host.recognition.fit_u_shrink).
    unknown_min_odds : float
        The odds r the "unknown" background must hold over the most probable object for a touch the
        open-set test rejects to be answered ``unknown`` (module docstring); 0 (default): the test alone.
    contact_calibration : mapping, optional
        ``{contact time s: {"temperature": T, "z_crit": z, ...}}`` (any of ``CONTACT_DIRECTIVES``):
        the calibration fitted at each contact time (a short touch's u is understated differently
        from a long one's, and its estimate biased differently, ISSUE #37); a touch is named with
        the entry nearest its heating time in ln t (:meth:`at_contact`), the scalars above when
        there is none.  Stored as ``#@ temperature@1s = ...`` directives.
    label : str
        Where the set came from (messages only).
    """

    def __init__(self, objects: Iterable[KnownObject], *, temperature: float = 1.0, z_crit: float = DEFAULT_Z_CRIT,
                 calibration_ln: float = 0.0, prior_unknown: float = DEFAULT_PRIOR_UNKNOWN,
                 alpha_u_growth: float = DEFAULT_ALPHA_U_GROWTH, bias_ln: float = 0.0, bias_slope: float = 0.0,
                 poor_fit_ln: float = 0.0, outlier_weight: float = 0.0, outlier_ln: float = DEFAULT_OUTLIER_LN,
                 u_var_scale: float = 1.0, u_shrink: float = 1.0, u_typ_ln0: float = DIRECTIVES["u_typ_ln0"].default,
                 u_typ_ln1: float = 0.0, u_typ_ln2: float = 0.0,
                 unknown_min_odds: float = 0.0, contact_calibration: Mapping[float, Mapping[str, float]] | None = None,
                 label: str = "<memory>") -> None:
        objs = tuple(objects)
        if not objs:
            raise ValueError("an object set needs at least one object")
        names = [o.name for o in objs]
        # Counted once (a 15 000-row set with list.count took seconds: ISSUE #35 §7).
        dup = sorted(n for n, c in Counter(names).items() if c > 1)
        if dup:
            raise ValueError(f"duplicate object names: {', '.join(dup)}")
        if UNKNOWN in names:
            raise ValueError(f"{UNKNOWN!r} is reserved for objects outside the set")
        self.temperature = check_value(DIRECTIVES["temperature"], temperature, "temperature")
        self.z_crit = check_value(DIRECTIVES["z_crit"], z_crit, "z_crit")
        self.calibration_ln = check_value(DIRECTIVES["calibration_ln"], calibration_ln, "calibration_ln")
        self.prior_unknown = check_value(DIRECTIVES["prior_unknown"], prior_unknown, "prior_unknown")
        self.alpha_u_growth = check_value(DIRECTIVES["alpha_u_growth"], alpha_u_growth, "alpha_u_growth")
        self.bias_ln = check_value(DIRECTIVES["bias_ln"], bias_ln, "bias_ln")
        self.bias_slope = check_value(DIRECTIVES["bias_slope"], bias_slope, "bias_slope")
        self.poor_fit_ln = check_value(DIRECTIVES["poor_fit_ln"], poor_fit_ln, "poor_fit_ln")
        self.outlier_weight = check_value(DIRECTIVES["outlier_weight"], outlier_weight, "outlier_weight")
        self.outlier_ln = check_value(DIRECTIVES["outlier_ln"], outlier_ln, "outlier_ln")
        self.u_var_scale = check_value(DIRECTIVES["u_var_scale"], u_var_scale, "u_var_scale")
        self.u_shrink = check_value(DIRECTIVES["u_shrink"], u_shrink, "u_shrink")
        self.u_typ_ln0 = check_value(DIRECTIVES["u_typ_ln0"], u_typ_ln0, "u_typ_ln0")
        self.u_typ_ln1 = check_value(DIRECTIVES["u_typ_ln1"], u_typ_ln1, "u_typ_ln1")
        self.u_typ_ln2 = check_value(DIRECTIVES["u_typ_ln2"], u_typ_ln2, "u_typ_ln2")
        self.unknown_min_odds = check_value(DIRECTIVES["unknown_min_odds"], unknown_min_odds, "unknown_min_odds")
        self.contact_calibration = _contact_table(contact_calibration)
        self._at: dict[float, ObjectSet] = {}
        self.label = label
        self.objects = objs
        self.names = tuple(names)
        self.classes = tuple(o.recognition_class for o in objs)
        self.class_names = tuple(dict.fromkeys(self.classes))
        self._class_index = np.array([self.class_names.index(c) for c in self.classes])
        self.ln_e_nominal = np.log([o.e_W_s05_m2K for o in objs])
        #: What each object is expected to read (its ln e plus the probe's fitted bias): the likelihood's centre.
        self.ln_e = self.ln_e_nominal + self.bias_of(self.ln_e_nominal)
        self.spread = np.array([o.spread_rel for o in objs], float)
        #: The u(ln e) a touch of each object typically states at this contact time (u_typ_ln0/1/2).
        self.u_typ = self.typical_u(self.ln_e_nominal)
        self.has_props = np.array([o.has_properties for o in objs])
        self.ln_alpha = np.log([o.alpha_m2_s if o.has_properties else 1.0 for o in objs])

    def bias_of(self, ln_e):
        """The probe's fitted bias of ln e at these ln e (``bias_ln + bias_slope (ln e - ln e_ref)``)."""
        return self.bias_ln + self.bias_slope * (np.asarray(ln_e, float) - math.log(BIAS_REF_E_W_s05_m2K))

    def typical_u(self, ln_e):
        """The stated u(ln e) typical of a touch of an object of this ln e: ``exp(a0 + a1 x + a2 x²)``, x = ln(e / e_ref)."""
        x = np.asarray(ln_e, float) - math.log(BIAS_REF_E_W_s05_m2K)
        return np.exp(self.u_typ_ln0 + self.u_typ_ln1 * x + self.u_typ_ln2 * x ** 2)

    def likelihood_u(self, u_ln_e, stated=True):
        """The u of ln e each object's likelihood uses for a touch stating ``u_ln_e``: ``u_typ^(1-b) u^b`` (shape ``(..., n)``).

        With ``u_shrink`` b < 1 the stated u is shrunk toward the u a touch of that object typically
        states: the stated u's touch-to-touch variation is partly noise (ISSUE #37, tactile as-built
        bench: within one wood the lowest-u third of touches scatters by 1.0-1.3 u, the highest third by
        0.6-0.85 u at 1 s).  b = 1: the stated u, bit for bit.  ``stated`` (bool, or one per touch):
        False for a width the set itself fixed (``poor_fit_ln``), which is not a noisy estimate and is
        used as it is.
        """
        u = np.asarray(u_ln_e, float)[..., None]
        if self.u_shrink == 1.0:
            return u
        shrunk = self.u_typ ** (1.0 - self.u_shrink) * u ** self.u_shrink
        if stated is True:
            return shrunk
        return np.where(np.asarray(stated, bool)[..., None], shrunk, u)

    # -- construction --------------------------------------------------------------
    @classmethod
    def from_library(cls, library=None, *, spread_rel: float = DEFAULT_SPREAD_REL, **kw) -> "ObjectSet":
        """The default set: every material of the library (a MaterialLibrary; default the packaged one).

        Its temperature and z_crit default to :data:`LIBRARY_CALIBRATION` (fitted
        on held-out simulated touches), so its posteriors are calibrated too.
        """
        lib = load_materials() if library is None else library
        for key, value in LIBRARY_CALIBRATION.items():
            kw.setdefault(key, value)
        objs = [KnownObject.from_properties(m.name, m.cls, m.k_W_mK, m.rho_kg_m3, m.c_J_kgK, spread_rel,
                                            source=m.source) for m in lib]
        kw.setdefault("label", getattr(lib, "path", "library"))
        return cls(objs, **kw)

    @classmethod
    def from_csv_text(cls, text: str, label: str = "<text>") -> "ObjectSet":
        """Parse and validate a CSV (module docstring); :class:`ObjectSetError` names line and column."""
        objs, directives = parse_csv(text, label)
        return cls(objs, label=label, **directives)

    @property
    def calibration(self) -> dict[str, float]:
        """The calibration scalars (the ``#@`` directives)."""
        return {k: getattr(self, k) for k in DIRECTIVES}

    def with_calibration(self, **changes: float) -> "ObjectSet":
        """The same objects with some calibration scalars replaced (keys of :data:`DIRECTIVES`)."""
        check_keys(changes, DIRECTIVES)
        return ObjectSet(self.objects, label=self.label, contact_calibration=self.contact_calibration,
                         **{**self.calibration, **changes})

    def with_contact_calibration(self, table: Mapping[float, Mapping[str, float]] | None) -> "ObjectSet":
        """The same objects and scalars with the per-contact-time table replaced (None: removed)."""
        return ObjectSet(self.objects, label=self.label, contact_calibration=table, **self.calibration)

    def at_contact(self, contact_time_s: float | None) -> "ObjectSet":
        """The set as calibrated for a touch heated ``contact_time_s``: the table's entry nearest in ln t.

        Without a table (or a contact time) the set itself.  The entry's values replace the
        scalars; the result carries no table of its own.
        """
        if not self.contact_calibration or contact_time_s is None or not (
                math.isfinite(contact_time_s) and contact_time_s > 0):
            return self
        t_fit = min(self.contact_calibration, key=lambda t: abs(math.log(t / contact_time_s)))
        got = self._at.get(t_fit)
        if got is None:
            got = ObjectSet(self.objects, label=self.label, **{**self.calibration, **self.contact_calibration[t_fit]})
            self._at[t_fit] = got
        return got

    def with_object(self, obj: KnownObject) -> "ObjectSet":
        """The set with ``obj`` added (or replacing the object of the same name); calibration kept."""
        objs = [o for o in self.objects if o.name != obj.name] + [obj]
        return ObjectSet(objs, label=self.label, contact_calibration=self.contact_calibration, **self.calibration)

    def without(self, names: Iterable[str]) -> "ObjectSet":
        """The set without the named objects (calibration kept)."""
        drop = set(names)
        return ObjectSet([o for o in self.objects if o.name not in drop], label=self.label,
                         contact_calibration=self.contact_calibration, **self.calibration)

    def to_csv_text(self) -> str:
        """The set as CSV, with its calibration as ``#@`` directives (round-trips through :meth:`from_csv_text`)."""
        # The outlier directives only when there is an outlier component: a set without one writes what it did.
        skip = (() if self.outlier_weight > 0 else ("outlier_weight", "outlier_ln")) + (
            () if self.u_var_scale != 1.0 else ("u_var_scale",)) + (
            () if self.u_shrink != 1.0 else ("u_shrink", "u_typ_ln0", "u_typ_ln1", "u_typ_ln2")) + (
            () if self.unknown_min_odds != 0.0 else ("unknown_min_odds",))
        lines = ["# ThermoTouch object set"] + [f"#@ {k} = {v!r}" for k, v in self.calibration.items()
                                                if k not in skip]
        lines += [f"#@ {contact_key(k, t)} = {v!r}" for t, entry in self.contact_calibration.items()
                  for k, v in entry.items()]
        header = ["name", "class", "k_W_mK", "rho_kg_m3", "c_J_kgK", "e_W_s05_m2K", "spread_rel", "source", "note"]
        rows = []
        for o in self.objects:
            props = ([repr(o.k_W_mK), repr(o.rho_kg_m3), repr(o.c_J_kgK), ""] if o.has_properties
                     else ["", "", "", repr(o.e_W_s05_m2K)])
            rows.append([o.name, o.cls, *props, repr(o.spread_rel), o.source, o.note])
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(header)
        w.writerows(rows)
        return "\n".join(lines) + "\n" + buf.getvalue()

    def __len__(self) -> int:
        return len(self.objects)

    def __contains__(self, name: object) -> bool:
        return name in self.names

    def __repr__(self) -> str:
        return f"ObjectSet({len(self)} objects from {self.label}, T={self.temperature:.3g}, z_crit={self.z_crit:.3g})"

    # -- likelihood ----------------------------------------------------------------
    def log_terms(self, ln_e, u_ln_e, *, ln_alpha=None, u_ln_alpha=None, corr=None, extra_var_ln_e=0.0,
                  stated=True):
        """Untempered terms of every object's log-likelihood, for one or many touches.

        Parameters
        ----------
        ln_e, u_ln_e : array_like
            Measured ln e and its standard uncertainty (any common shape ``...``).
        ln_alpha, u_ln_alpha, corr : array_like, optional
            A measured ln α, its standard uncertainty and the correlation of the
            ln e and ln α errors (default 0). NaN in ``ln_alpha`` marks a touch
            without α (its rows are the e-only terms).
        extra_var_ln_e : float
            Added to every object's (untempered) variance of ln e: the outlier component's
            ``outlier_ln² / T`` (:meth:`outlier_terms`).
        stated : bool or array_like of bool
            Whether ``u_ln_e`` is the touch's stated u (shrunk by :meth:`likelihood_u`) or a width the
            set fixed (used as it is); one per touch or one for all.

        Returns
        -------
        q : (..., n) ndarray
            Squared standardised (Mahalanobis) distance over the properties each object has.
        half_logdet : (..., n) ndarray
            Half the log-determinant of each object's covariance (broad terms included).
        dof : (..., n) ndarray of int
            Number of properties in ``q``. The log-likelihood at temperature T is
            ``-0.5 q / T - half_logdet - dof' ln sqrt(2 pi T)`` (``dof'`` counting broad terms).
        """
        x = np.asarray(ln_e, float)[..., None]
        u = self.likelihood_u(u_ln_e, stated)
        var_e = self.u_var_scale * u ** 2 + self.spread ** 2 + self.calibration_ln ** 2
        if extra_var_ln_e:
            var_e = var_e + extra_var_ln_e
        de = x - self.ln_e
        q_e = de ** 2 / var_e
        hld_e = 0.5 * np.log(var_e)
        dof_e = np.ones(np.broadcast(x, self.ln_e).shape, int)
        if ln_alpha is None:
            return q_e, hld_e, dof_e
        if u_ln_alpha is None:
            raise ValueError("a measured alpha needs its uncertainty")
        xa = np.asarray(ln_alpha, float)[..., None]
        has = np.isfinite(xa)
        ua = np.where(has, effective_u_ln_alpha(np.asarray(u_ln_alpha, float)[..., None], self.alpha_u_growth), 1.0)
        r = np.where(has, np.asarray(0.0 if corr is None else corr, float)[..., None], 0.0)
        c_ea = r * math.sqrt(self.u_var_scale) * u * ua   # the scaled u(ln e) times u(ln α)
        var_a = ua ** 2 + self.spread ** 2
        det = var_e * var_a - c_ea ** 2
        da = np.where(has, xa, 0.0) - self.ln_alpha
        q_j = (var_a * de ** 2 - 2.0 * c_ea * de * da + var_e * da ** 2) / det
        props = self.has_props & has
        q = np.where(props, q_j, q_e)
        # An object without alpha: the broad term's density at its centre (the measurement's own value).
        hld_b = hld_e + 0.5 * np.log(ua ** 2 + BROAD_LN ** 2)
        hld = np.where(props, 0.5 * np.log(det), np.where(has, hld_b, hld_e))
        dof = dof_e + props
        return q, hld, dof

    def outlier_terms(self, ln_e, u_ln_e, *, temperature: float | None = None, outlier_ln: float | None = None,
                      **alpha):
        """:meth:`log_terms` of the outlier component at a temperature: σ_out² added to the tempered var of ln e."""
        t = self.temperature if temperature is None else temperature
        s = self.outlier_ln if outlier_ln is None else outlier_ln
        return self.log_terms(ln_e, u_ln_e, extra_var_ln_e=s ** 2 / t, **alpha)

    @staticmethod
    def mixture_log_weight(lw_core, lw_out, outlier_weight: float) -> np.ndarray:
        """``log((1 - ε) exp(lw_core) + ε exp(lw_out))``, element-wise: the one definition of the mixture."""
        return np.logaddexp(math.log1p(-outlier_weight) + np.asarray(lw_core),
                            math.log(outlier_weight) + np.asarray(lw_out))

    def posteriors(self, q, half_logdet, *, temperature: float | None = None, outlier=None,
                   outlier_weight: float | None = None) -> np.ndarray:
        """Closed-set posteriors over the objects (equal priors) from :meth:`log_terms` at a temperature.

        ``outlier``: ``(q, half_logdet)`` of :meth:`outlier_terms` (at the same temperature), mixed
        in with weight ``outlier_weight`` (default the set's); without it, or at weight 0, the Gaussian.
        """
        t = self.temperature if temperature is None else temperature
        eps = self.outlier_weight if outlier_weight is None else outlier_weight
        lw = -0.5 * np.asarray(q) / t - np.asarray(half_logdet)
        if outlier is not None and eps > 0:
            lw = self.mixture_log_weight(lw, -0.5 * np.asarray(outlier[0]) / t - np.asarray(outlier[1]), eps)
        lw = lw - lw.max(axis=-1, keepdims=True)
        w = np.exp(lw)
        return w / w.sum(axis=-1, keepdims=True)

    # -- recognition ---------------------------------------------------------------
    def classify(self, e: float, u_ln_e: float, *, alpha: float | None = None, u_ln_alpha: float | None = None,
                 corr: float = 0.0, top: int = 3, stated: bool = True) -> Recognition:
        """Which object a touch with effusivity ``e`` (relative standard uncertainty ``u_ln_e``) was.

        ``alpha`` (with ``u_ln_alpha`` and ``corr``, the correlation of the ln e
        and ln α errors) sharpens the answer when a probe measures it (the
        small-heater probe's fit, :func:`measured_alpha`); do not pass the default
        method's prior-based α (a function of e: it adds nothing).  The batch of one of
        :meth:`classify_many` (:func:`edge.recognition.classify.classify_rows`): one definition.
        ``stated`` False: ``u_ln_e`` is a width the set fixed (``poor_fit_ln``), not shrunk (:meth:`likelihood_u`).
        """
        check_touch(e, u_ln_e, alpha, u_ln_alpha, corr)
        return classify_rows(self, [e], [u_ln_e], [alpha], [u_ln_alpha], [corr], top, [stated])[0]

    def classify_many(self, e, u_ln_e, *, alpha=None, u_ln_alpha=None, corr=0.0, top: int = 3,
                      stated=True) -> list[Recognition]:
        """:meth:`classify` of many touches at once, every number the per-touch one to the bit.

        Parameters
        ----------
        e, u_ln_e : array_like
            Each touch's effusivity and relative standard uncertainty (1-D, or scalars broadcast).
        alpha, u_ln_alpha, corr : array_like, optional
            Each touch's measured α, its u(ln α) and correlation (as :meth:`classify`); NaN or None in
            ``alpha`` marks a touch without α.
        top : int
            Number of candidates listed.
        stated : bool or array_like of bool
            As :meth:`classify`, per touch or for all.

        Returns
        -------
        list of Recognition
            One per touch; ValueError (naming the touch) where :meth:`classify` would raise one.
        """
        e_t, u_t, a_t, ua_t, r_t = (np.broadcast_arrays(*(np.asarray(v if v is not None else np.nan, float)
                                                          for v in (e, u_ln_e, alpha, u_ln_alpha, corr))))
        if e_t.ndim > 1:
            raise ValueError(f"classify_many takes 1-D arrays of touches, got shape {e_t.shape}")
        es, us = np.atleast_1d(e_t).tolist(), np.atleast_1d(u_t).tolist()
        alphas = [None if math.isnan(a) else a for a in np.atleast_1d(a_t).tolist()]
        uas = [None if math.isnan(v) else v for v in np.atleast_1d(ua_t).tolist()]
        rs = np.atleast_1d(r_t).tolist()
        for k, touch in enumerate(zip(es, us, alphas, uas, rs)):
            try:
                check_touch(*touch)
            except ValueError as exc:
                raise ValueError(f"touch {k}: {exc}") from None
        st = np.broadcast_to(np.asarray(stated, bool), np.shape(np.atleast_1d(e_t))).tolist()
        return classify_rows(self, es, us, alphas, uas, rs, top, st) if es else []

    def classify_estimate(self, estimate: Mapping, *, top: int = 3,
                          contact_time_s: float | None = None, stated: bool = True) -> Recognition | None:
        """:meth:`classify` of an estimate's dict (``Estimate.to_dict()`` or the small heater's), None without e.

        e and its u (a missing u counts as 0: the objects' spreads still set
        the widths), and α where the probe measured it (:func:`measured_alpha`).
        One definition for every output (:func:`recognition_fields`) and the host.
        ``contact_time_s`` (the touch's heating time) picks the set's calibration at that contact
        time (:meth:`at_contact`).  ``stated`` False: the estimate's u is a width the set fixed (:meth:`classify`).
        """
        e = estimate.get("effusivity_W_s05_m2K")
        if e is None or not (math.isfinite(float(e)) and float(e) > 0):
            return None
        u = estimate.get("effusivity_W_s05_m2K_u")
        u_ln_e = float(u) / float(e) if u is not None and math.isfinite(float(u)) and float(u) >= 0 else 0.0
        a = measured_alpha(estimate)
        kw = {} if a is None else {"alpha": a[0], "u_ln_alpha": a[1], "corr": a[2]}
        # A tiny floor: an object with zero spread and a zero uncertainty would divide by zero.
        return self.at_contact(contact_time_s).classify(float(e), max(u_ln_e, 1e-9), top=top, stated=stated, **kw)

    # -- open-set design rates -----------------------------------------------------
    def acceptance_intervals(self, u_ln_e: float) -> np.ndarray:
        """The ln e intervals the open-set test accepts at ``u_ln_e`` (e alone), merged and sorted.

        An e-only touch is accepted when ``|ln e - ln e_i| <= z_crit sqrt(T v_i)``
        for some object, ``v_i = u² + spread_i² + calibration_ln²``; the
        acceptance region is the union of those intervals. Returns an
        ``(m, 2)`` array of disjoint ``[lo, hi]`` rows.
        """
        half = self.z_crit * np.sqrt(self.temperature * (u_ln_e ** 2 + self.spread ** 2 + self.calibration_ln ** 2))
        iv = np.column_stack([self.ln_e - half, self.ln_e + half])
        iv = iv[np.argsort(iv[:, 0])]
        merged = [iv[0].copy()]
        for lo, hi in iv[1:]:
            if lo <= merged[-1][1]:  # overlapping neighbours: one interval
                merged[-1][1] = max(merged[-1][1], hi)
            else:
                merged.append(np.array([lo, hi]))
        return np.array(merged)

    def acceptance_probability(self, mean_ln_e: float, sd_ln_e: float, u_ln_e: float) -> float:
        """Design probability that the open-set test accepts a touch (e alone).

        The touch's measured ln e is taken as normal with mean ``mean_ln_e``
        and standard deviation ``sd_ln_e`` (specimen spread and measurement
        noise together), reported with uncertainty ``u_ln_e``. For an object of
        the set, ``1 -`` this is the design false-reject rate (with
        ``sd_ln_e = sqrt(spread² + u²)``); for an object outside it, this is
        the design false-accept rate -- the best an e-only test of this width
        can do, whatever the method, so benchmarks can tell "the test is
        wrong" from "the object's e lies inside an object's spread".
        """
        if not sd_ln_e > 0:
            raise ValueError(f"sd_ln_e must be positive, got {sd_ln_e!r}")
        iv = (self.acceptance_intervals(u_ln_e) - mean_ln_e) / (sd_ln_e * math.sqrt(2.0))
        # P(lo < x < hi) = (erf(hi') - erf(lo')) / 2, via erfc for accuracy in the tails.
        return float(sum(0.5 * (math.erfc(lo) - math.erfc(hi)) for lo, hi in iv))

    # -- separability -------------------------------------------------------------
    def confusion_pairs(self, u_ln_e: float, *, factor: float = 2.0, involving: str | None = None,
                        grid_step: float | None = None) -> Confusion:
        """Pairs of objects e alone cannot separate at ``u_ln_e``, and the Bayes accuracy ceiling.

        A pair is listed when ``|Δ ln e| < factor * sqrt(v_a + v_b)`` with
        ``v = u_ln_e² + spread² + calibration_ln²`` (so ``2 sqrt(2u² + spreads²)``
        by default). ``involving`` keeps the pairs with that object (the
        ``objects add`` warning). The ceiling is the accuracy of the
        Bayes-optimal rule on e alone with equal priors, ``∫ max_i p_i(x) dx``,
        integrated on a grid in ln e (class ceiling: ``∫ max_c Σ_{i∈c} p_i``).
        """
        var = u_ln_e ** 2 + self.spread ** 2 + self.calibration_ln ** 2
        if np.any(var <= 0):
            raise ValueError("an object with zero spread needs u_ln_e > 0")
        pairs = []
        n = len(self)
        for i in range(n):
            for j in range(i + 1, n):
                if involving is not None and involving not in (self.names[i], self.names[j]):
                    continue
                d = abs(float(self.ln_e[i] - self.ln_e[j]))
                thr = factor * math.sqrt(var[i] + var[j])
                if d < thr:
                    a, b = (i, j) if self.ln_e[i] <= self.ln_e[j] else (j, i)
                    pairs.append(ConfusionPair(self.names[a], self.names[b], d, thr))
        pairs.sort(key=lambda p: p.delta_ln_e / p.threshold_ln)
        sd = np.sqrt(var)
        step = grid_step or float(sd.min()) / 20.0
        x = np.arange(float((self.ln_e - 8 * sd).min()), float((self.ln_e + 8 * sd).max()) + step, step)
        acc = cls_acc = 0.0
        for lo in range(0, x.size, 4096):  # chunks keep memory flat for big sets
            xs = x[lo:lo + 4096]
            dens = np.exp(-0.5 * ((xs[:, None] - self.ln_e) / sd) ** 2) / (sd * math.sqrt(2 * math.pi)) / n
            acc += float(dens.max(axis=1).sum())
            by_class = np.zeros((xs.size, len(self.class_names)))
            np.add.at(by_class.T, self._class_index, dens.T)
            cls_acc += float(by_class.max(axis=1).sum())
        return Confusion(float(u_ln_e), tuple(pairs), min(1.0, acc * step), min(1.0, cls_acc * step))
