"""The objects of a set and the CSV format a user writes them in.

:class:`KnownObject` is one object (name, class, and either k, ρ, c or the
effusivity e alone, plus the specimen-to-specimen spread of its properties);
:func:`parse_csv` reads a set's CSV into objects and its ``#@`` directives
(the calibration stored with the set), reporting every problem with its line
and column (:class:`ObjectSetError`).

CSV format
----------
Lines whose first non-blank character is ``#`` and blank lines are comments,
except *directives* ``#@ key = value`` (``temperature``, ``z_crit``,
``calibration_ln``, ``prior_unknown``, ``alpha_u_growth``, ``bias_ln``, ``bias_slope``, ``poor_fit_ln``,
``outlier_weight``, ``outlier_ln``, ``u_var_scale``, ``u_shrink``, ``u_typ_ln0``, ``u_typ_ln1``, ``u_typ_ln2``,
``unknown_min_odds``:
the calibration stored with the set; all but ``prior_unknown`` and ``alpha_u_growth`` may also be given
per contact time, ``#@ bias_ln@1s = 0.05``). The first
other line is the header: ``name``, ``class``, and either ``k_W_mK``,
``rho_kg_m3``, ``c_J_kgK`` or ``e_W_s05_m2K`` (both groups may be present;
each row fills exactly one of them), and optionally ``spread_rel``,
``source``, ``note``. Values are validated by :mod:`edge.schema`; every
problem is reported with its 1-based line and its column
(:class:`ObjectSetError`).
"""

from __future__ import annotations

import csv
import math
import re
from dataclasses import dataclass
from typing import Iterable

from edge.physics.materials import (C_RANGE_J_KGK, CLASSES, K_RANGE_W_MK, RECOGNITION_CLASS, RHO_C_RANGE_J_M3K,
                                    RHO_RANGE_kg_m3)
from edge.recognition.touch import DEFAULT_ALPHA_U_GROWTH
from edge.schema import Field, SchemaError, check_keys, check_value

__all__ = ["UNKNOWN", "DEFAULT_SPREAD_REL", "DEFAULT_Z_CRIT", "DEFAULT_PRIOR_UNKNOWN", "DEFAULT_OUTLIER_LN",
           "UNKNOWN_LN_E_SPAN", "COLUMNS", "DIRECTIVES", "BIAS_REF_E_W_s05_m2K", "CONTACT_DIRECTIVES", "contact_key", "Issue", "ObjectSetError",
           "KnownObject", "parse_csv"]

#: The answer when the touched object is none of the set's.
UNKNOWN = "unknown"
#: Specimen-to-specimen spread of an object's e (and α), relative (lognormal sd).
DEFAULT_SPREAD_REL = 0.05
#: Critical standardised distance of the open-set test before a calibration is fitted
#: (nominal in-set acceptance 98.8 % for one property).
DEFAULT_Z_CRIT = 2.5
_E_RANGE = (math.sqrt(K_RANGE_W_MK[0] * RHO_C_RANGE_J_M3K[0]), math.sqrt(K_RANGE_W_MK[1] * RHO_C_RANGE_J_M3K[1]))
#: Width in ln e of the flat density of the "unknown" hypothesis (the plausible range of e).
UNKNOWN_LN_E_SPAN = math.log(_E_RANGE[1] / _E_RANGE[0])
#: Prior probability that a touched object is outside the set, before the user says otherwise.
DEFAULT_PRIOR_UNKNOWN = 0.05
#: Extra sd of ln e of the likelihood's outlier component before one is fitted (only used when
#: ``outlier_weight`` > 0): a short touch's failures read e a factor 1.5-2.5 off (ISSUE #37).
DEFAULT_OUTLIER_LN = 0.7
_PROPS = ("k_W_mK", "rho_kg_m3", "c_J_kgK")

#: The CSV columns and their schema (values arrive as text and are converted first).
COLUMNS: dict[str, Field] = {
    "name": Field("str", doc="unique name of the object (not 'unknown')", lo=1, hi=64),
    "class": Field("str", doc="material class", choices=CLASSES),
    "k_W_mK": Field("float", None, "thermal conductivity, W/(m K)", lo=K_RANGE_W_MK[0], hi=K_RANGE_W_MK[1]),
    "rho_kg_m3": Field("float", None, "density, kg/m^3", lo=RHO_RANGE_kg_m3[0], hi=RHO_RANGE_kg_m3[1]),
    "c_J_kgK": Field("float", None, "specific heat, J/(kg K)", lo=C_RANGE_J_KGK[0], hi=C_RANGE_J_KGK[1]),
    "e_W_s05_m2K": Field("float", None, "effusivity, W s^0.5/(m^2 K)", lo=_E_RANGE[0], hi=_E_RANGE[1]),
    "spread_rel": Field("float", DEFAULT_SPREAD_REL, "specimen spread of e (relative sd)", lo=0.0, hi=1.0),
    "source": Field("str", "", "where the values come from", hi=256),
    "note": Field("str", "", "free text", hi=256),
}
_NUMERIC_COLUMNS = ("k_W_mK", "rho_kg_m3", "c_J_kgK", "e_W_s05_m2K", "spread_rel")

#: ``#@ key = value`` directives: the calibration stored with the set.
DIRECTIVES: dict[str, Field] = {
    "temperature": Field("float", 1.0, "scale on every variance (fitted on held-out touches)", lo=0.0, lo_open=True,
                         hi=1e4),
    "z_crit": Field("float", DEFAULT_Z_CRIT, "critical standardised distance of the open-set test", lo=0.5, hi=20.0),
    "calibration_ln": Field("float", 0.0, "extra systematic sd of ln e (probe calibration)", lo=0.0, hi=1.0),
    "prior_unknown": Field("float", DEFAULT_PRIOR_UNKNOWN, "prior probability of touching an object outside the set",
                           lo=0.0, hi=1.0, lo_open=True, hi_open=True),
    "alpha_u_growth": Field("float", DEFAULT_ALPHA_U_GROWTH, "growth a of a measured alpha's uncertainty, "
                            "u (1 + a u) (fitted on held-out touches)", lo=0.0, hi=100.0),
    "bias_ln": Field("float", 0.0, "the probe's bias of ln e at BIAS_REF_E_W_s05_m2K (fitted on held-out "
                     "touches of other probes)", lo=-2.0, hi=2.0),
    "bias_slope": Field("float", 0.0, "change of that bias per unit ln e", lo=-2.0, hi=2.0),
    "poor_fit_ln": Field("float", 0.0, "sd of ln e with which a withheld poor_fit chain e names an object "
                         "(0: such a touch names none)", lo=0.0, hi=3.0),
    "outlier_weight": Field("float", 0.0, "weight eps of the likelihood's broad outlier component (estimator "
                            "failures; 0: the Gaussian alone)", lo=0.0, hi=0.5),
    "outlier_ln": Field("float", DEFAULT_OUTLIER_LN, "extra sd of ln e of that outlier component", lo=0.01, hi=5.0),
    "u_var_scale": Field("float", 1.0, "scale on the measurement's variance u^2 of ln e alone, the specimen "
                         "spread left as stated (fitted on held-out touches; 1: the stated u)", lo=0.0, lo_open=True,
                         hi=1e4),
    "u_shrink": Field("float", 1.0, "power b on the stated u in the likelihood's u_j = u_typ_j^(1-b) u^b, u_typ_j "
                      "the u a touch of object j typically states (u_typ_ln0/1/2); 1: the stated u as it is",
                      lo=0.0, hi=1.0),
    "u_typ_ln0": Field("float", math.log(0.03), "ln of the typical stated u(ln e) at BIAS_REF_E_W_s05_m2K",
                       lo=-12.0, hi=2.0),
    "u_typ_ln1": Field("float", 0.0, "slope of ln u_typ per unit ln e", lo=-5.0, hi=5.0),
    "u_typ_ln2": Field("float", 0.0, "curvature of ln u_typ per unit (ln e)^2", lo=-5.0, hi=5.0),
    "unknown_min_odds": Field("float", 0.0, "odds the 'unknown' background must hold over the most probable "
                              "object for a touch the open-set test rejects to be answered unknown (0: the test "
                              "alone; 1: unknown only when it is the most probable hypothesis)", lo=0.0, hi=1e6),
}
#: Effusivity (W s^0.5/(m^2 K)) at which ``bias_ln`` is the bias: mid-range (the polymers and woods a
#: short touch reads worst lie a unit of ln e below it, the metals three above).
BIAS_REF_E_W_s05_m2K = 1000.0


# -- errors ----------------------------------------------------------------------------
@dataclass(frozen=True)
class Issue:
    """One problem in an object-set CSV: 1-based ``line`` (0: the file), ``column`` and ``message``."""

    line: int
    column: str
    message: str

    def __str__(self) -> str:
        where = f"line {self.line}" if self.line else "file"
        if self.column:
            where += f", column '{self.column}'"
        return f"{where}: {self.message}"


class ObjectSetError(ValueError):
    """An object-set CSV is malformed; ``issues`` lists every problem with its line and column."""

    def __init__(self, issues: Iterable[Issue], label: str = "") -> None:
        self.issues = tuple(issues)
        self.label = label
        n = len(self.issues)
        head = f"invalid object set{' ' + label if label else ''} ({n} problem{'s' if n != 1 else ''}):"
        super().__init__("\n".join([head] + ["  " + str(i) for i in self.issues]))


# -- the objects -----------------------------------------------------------------------
@dataclass(frozen=True)
class KnownObject:
    """One object of a set: either (k, ρ, c) or e alone, and its specimen spread."""

    name: str
    cls: str
    e_W_s05_m2K: float
    k_W_mK: float | None = None
    rho_kg_m3: float | None = None
    c_J_kgK: float | None = None
    spread_rel: float = DEFAULT_SPREAD_REL
    source: str = ""
    note: str = ""

    @classmethod
    def from_properties(cls, name: str, cls_: str, k_W_mK: float, rho_kg_m3: float, c_J_kgK: float,
                        spread_rel: float = DEFAULT_SPREAD_REL, **kw) -> "KnownObject":
        """An object given by k, ρ, c (e derived)."""
        e = math.sqrt(k_W_mK * rho_kg_m3 * c_J_kgK)
        return cls(name, cls_, e, k_W_mK, rho_kg_m3, c_J_kgK, spread_rel, **kw)

    @property
    def recognition_class(self) -> str:
        """The class results name (:data:`edge.physics.materials.RECOGNITION_CLASS` of ``cls``)."""
        return RECOGNITION_CLASS[self.cls]

    @property
    def has_properties(self) -> bool:
        """True when k, ρ and c are known (so k and α can be compared too)."""
        return self.k_W_mK is not None

    @property
    def alpha_m2_s(self) -> float | None:
        """Thermal diffusivity, or None for an object given by e alone."""
        return None if self.k_W_mK is None else self.k_W_mK / (self.rho_kg_m3 * self.c_J_kgK)



# -- CSV parsing -------------------------------------------------------------------------
def parse_csv(text: str, label: str) -> tuple[list[KnownObject], dict]:
    """The objects and ``#@`` directives of a set's CSV (module docstring); :class:`ObjectSetError` lists every problem."""
    issues: list[Issue] = []
    header: list[str] | None = None
    header_line = 0
    objs: list[KnownObject] = []
    first_line: dict[str, int] = {}
    directives: dict[str, float] = {}

    for lineno, raw in enumerate(text.splitlines(), start=1):
        stripped = raw.strip()
        if stripped.startswith("#@"):
            key, sep, value = stripped[2:].partition("=")
            key = key.strip()
            try:
                if not sep:
                    raise SchemaError("", "directive must read '#@ key = value'")
                per = _contact_key(key)
                if per is not None:
                    # ``#@ temperature@1s = 1.2``: the calibration at one contact time (ObjectSet.at_contact).
                    name, t_s = per
                    directives.setdefault("contact_calibration", {}).setdefault(t_s, {})[name] = check_value(
                        DIRECTIVES[name], _number(value.strip(), key), key)
                    continue
                check_keys({key: None}, DIRECTIVES)
                directives[key] = check_value(DIRECTIVES[key], _number(value.strip(), key), key)
            except SchemaError as exc:
                issues.append(Issue(lineno, exc.path or "#@", exc.message))
            continue
        if not stripped or stripped.startswith("#"):
            continue
        try:
            fields = [f.strip() for f in next(csv.reader([raw]))]
        except csv.Error as exc:  # e.g. a field over the csv module's 131 072-character limit
            issues.append(Issue(lineno, "<line>", f"not a CSV row: {exc}"))
            break
        if header is None:
            header, header_line = fields, lineno
            try:
                check_keys(dict.fromkeys(fields), COLUMNS)
            except SchemaError as exc:
                issues.append(Issue(lineno, exc.path or "<empty>", exc.message))
            for col in sorted({c for c in fields if fields.count(c) > 1}):
                issues.append(Issue(lineno, col, "column appears more than once in the header"))
            for col in ("name", "class"):
                if col not in fields:
                    issues.append(Issue(lineno, col, "required column is missing from the header"))
            has_props = all(c in fields for c in _PROPS)
            if not has_props and "e_W_s05_m2K" not in fields:
                missing = [c for c in _PROPS if c not in fields]
                issues.append(Issue(lineno, missing[0], "the header needs k_W_mK, rho_kg_m3 and c_J_kgK, "
                                                        "or e_W_s05_m2K"))
            if issues:
                break  # rows cannot be read against a broken header
            continue
        if len(fields) != len(header):
            col = header[len(fields)] if len(fields) < len(header) else f"<extra field {len(header) + 1}>"
            issues.append(Issue(lineno, col, f"row has {len(fields)} fields but the header (line {header_line}) "
                                             f"has {len(header)}"))
            continue
        obj = _parse_row(dict(zip(header, fields)), lineno, issues)
        if obj is None:
            continue
        if obj.name in first_line:
            issues.append(Issue(lineno, "name", f"duplicate name {obj.name!r}: lines {first_line[obj.name]} "
                                                f"and {lineno}"))
            continue
        first_line[obj.name] = lineno
        objs.append(obj)

    if header is None and not issues:
        issues.append(Issue(0, "", "no header line (empty or only comments)"))
    elif not issues and not objs:
        issues.append(Issue(0, "", "header present but no object rows"))
    if issues:
        raise ObjectSetError(issues, label)
    return objs, directives


#: Directives that may be given per contact time (``#@ temperature@0.5s = ...``).
CONTACT_DIRECTIVES = ("temperature", "z_crit", "calibration_ln", "bias_ln", "bias_slope", "poor_fit_ln",
                      "outlier_weight", "outlier_ln", "u_var_scale", "u_shrink", "u_typ_ln0", "u_typ_ln1", "u_typ_ln2",
                      "unknown_min_odds")
_CONTACT_KEY = re.compile(r"^(" + "|".join(CONTACT_DIRECTIVES) + r")@([0-9]*\.?[0-9]+)s$")


def _contact_key(key: str) -> tuple[str, float] | None:
    """``("temperature", 0.5)`` for ``temperature@0.5s``; None for any other key."""
    m = _CONTACT_KEY.match(key)
    if m is None:
        return None
    t_s = float(m.group(2))
    if not (0.0 < t_s <= 600.0):
        raise SchemaError(key, f"contact time must lie in (0, 600] s, got {t_s:g}")
    return m.group(1), t_s


def contact_key(name: str, t_s: float) -> str:
    """The directive key of ``name`` at contact time ``t_s`` (inverse of the parser's)."""
    return f"{name}@{t_s:g}s"


def _number(text: str, path: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise SchemaError(path, f"must be a number, got {text!r}") from None


def _parse_row(row: dict[str, str], lineno: int, issues: list[Issue]) -> KnownObject | None:
    vals: dict = {}
    ok = True
    for col, text in row.items():
        f = COLUMNS[col]
        if text == "":
            if f.required:
                issues.append(Issue(lineno, col, "required field is empty"))
                ok = False
            continue
        try:
            vals[col] = check_value(f, _number(text, col) if col in _NUMERIC_COLUMNS else text, col)
        except SchemaError as exc:
            issues.append(Issue(lineno, col, exc.message))
            ok = False
    if not ok:
        return None
    if vals["name"] == UNKNOWN:
        issues.append(Issue(lineno, "name", f"{UNKNOWN!r} is reserved for objects outside the set"))
        return None
    given = [c for c in _PROPS if c in vals]
    if "e_W_s05_m2K" in vals and given:
        issues.append(Issue(lineno, "e_W_s05_m2K", "give either e_W_s05_m2K or k_W_mK, rho_kg_m3, c_J_kgK, not both"))
        return None
    if "e_W_s05_m2K" not in vals and len(given) < 3:
        missing = [c for c in _PROPS if c not in vals]
        issues.append(Issue(lineno, missing[0], "required field is empty (give k_W_mK, rho_kg_m3 and c_J_kgK, "
                                                "or e_W_s05_m2K)"))
        return None
    extra = dict(spread_rel=vals.get("spread_rel", DEFAULT_SPREAD_REL), source=vals.get("source", ""),
                 note=vals.get("note", ""))
    if given:
        rc = vals["rho_kg_m3"] * vals["c_J_kgK"]
        if not RHO_C_RANGE_J_M3K[0] <= rc <= RHO_C_RANGE_J_M3K[1]:
            issues.append(Issue(lineno, "rho_kg_m3*c_J_kgK", f"volumetric heat capacity {rc:.4g} J/(m^3 K) is outside "
                                                             f"[{RHO_C_RANGE_J_M3K[0]:g}, {RHO_C_RANGE_J_M3K[1]:g}]"))
            return None
        return KnownObject.from_properties(vals["name"], vals["class"], vals["k_W_mK"], vals["rho_kg_m3"],
                                           vals["c_J_kgK"], **extra)
    return KnownObject(vals["name"], vals["class"], vals["e_W_s05_m2K"], **extra)
