"""NIST ITS-90 type K thermocouple reference and inverse functions.

Coefficients are those of NIST Monograph 175 / the NIST ITS-90 thermocouple
database (type K). The reference function gives the EMF ``E`` (mV) of a type K
thermocouple whose reference junction is at 0 °C; the inverse functions give
the temperature for an EMF with the published accuracy (±0.05 °C at most).

Cold-junction compensation with a reference junction at ``T_cj``:
``T_hot = temperature_C(E_meas + emf_mV(T_cj))`` (see :func:`hot_junction_C`).

All functions accept scalars or array-likes (NumPy-vectorised) and return a
float for scalar input, an ndarray otherwise. Out-of-range input raises
ValueError naming the argument and the valid range.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "T_MIN_C", "T_MAX_C", "E_MIN_MV", "E_MAX_MV", "INVERSE_E_MIN_MV",
    "emf_mV", "temperature_C", "seebeck_uV_per_K", "hot_junction_C",
]

T_MIN_C = -270.0
T_MAX_C = 1372.0

# Reference function, -270 °C .. 0 °C: E = sum c_i t^i
_C_NEG = np.array([
    0.000000000000e00, 0.394501280250e-01, 0.236223735980e-04,
    -0.328589067840e-06, -0.499048287770e-08, -0.675090591730e-10,
    -0.574103274280e-12, -0.310888728940e-14, -0.104516093650e-16,
    -0.198892668780e-19, -0.163226974860e-22,
])
# Reference function, 0 °C .. 1372 °C: E = sum c_i t^i + a0 exp(a1 (t - a2)^2)
_C_POS = np.array([
    -0.176004136860e-01, 0.389212049750e-01, 0.185587700320e-04,
    -0.994575928740e-07, 0.318409457190e-09, -0.560728448890e-12,
    0.560750590590e-15, -0.320207200030e-18, 0.971511471520e-22,
    -0.121047212750e-25,
])
_A0, _A1, _A2 = 0.118597600000e00, -0.118343200000e-03, 0.126968600000e03

# Inverse functions t = sum d_i E^i, three EMF ranges (mV).
_D_NEG = np.array([  # -5.891 .. 0 mV (-200 .. 0 °C), error -0.02 .. 0.04 °C
    0.0000000e00, 2.5173462e01, -1.1662878e00, -1.0833638e00, -8.9773540e-01,
    -3.7342377e-01, -8.6632643e-02, -1.0450598e-02, -5.1920577e-04,
])
_D_MID = np.array([  # 0 .. 20.644 mV (0 .. 500 °C), error -0.05 .. 0.04 °C
    0.000000e00, 2.508355e01, 7.860106e-02, -2.503131e-01, 8.315270e-02,
    -1.228034e-02, 9.804036e-04, -4.413030e-05, 1.057734e-06, -1.052755e-08,
])
_D_HIGH = np.array([  # 20.644 .. 54.886 mV (500 .. 1372 °C), error -0.05 .. 0.06 °C
    -1.318058e02, 4.830222e01, -1.646031e00, 5.464731e-02, -9.650715e-04,
    8.802193e-06, -3.110810e-08,
])

# Range limits are the reference function at the end points (the NIST tables
# print them rounded to 1 µV: -5.891, -6.458, 54.886 mV).
INVERSE_E_MIN_MV = -5.8915  # E(-200 °C); NIST inverse functions start there
E_MIN_MV = -6.4578          # E(-270 °C)
E_MAX_MV = 54.8865          # E(1372 °C)
_E_SPLIT_MV = 20.644


def _polyval(coeffs: np.ndarray, x: np.ndarray) -> np.ndarray:
    # np.polyval wants highest order first; NIST lists lowest first.
    return np.polyval(coeffs[::-1], x)


# dE/dt coefficients (lowest order first), for seebeck_uV_per_K.
_DC_NEG = np.arange(1, _C_NEG.size) * _C_NEG[1:]
_DC_POS = np.arange(1, _C_POS.size) * _C_POS[1:]


def _horner(c_high_first: tuple[float, ...], x: float) -> float:
    # np.polyval's own recurrence (y = y x + c from y = 0) in Python floats: the same IEEE
    # operations in the same order, so a scalar gives the array path's value to the bit.
    y = 0.0
    for c in c_high_first:
        y = y * x + c
    return y


def _high_first(coeffs: np.ndarray) -> tuple[float, ...]:
    return tuple(float(c) for c in coeffs[::-1])


# The scalar path: one conversion per converter sample in the drivers and the chip emulators, where
# NumPy's per-call overhead on 0-d arrays (every branch evaluated, then np.where) was 30-75 us a call.
_H = {name: _high_first(c) for name, c in
      (("c_neg", _C_NEG), ("c_pos", _C_POS), ("dc_neg", _DC_NEG), ("dc_pos", _DC_POS),
       ("d_neg", _D_NEG), ("d_mid", _D_MID), ("d_high", _D_HIGH))}


def _real_scalar(x) -> float | None:
    """``x`` as a float when it is a real Python or NumPy scalar (not a bool), else None."""
    if isinstance(x, float) or (isinstance(x, (int, np.integer)) and not isinstance(x, bool)):
        return float(x)
    return None


def _as_array(x, name: str) -> tuple[np.ndarray, bool]:
    arr = np.asarray(x, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {x!r}")
    return arr, arr.ndim == 0


def _out(arr: np.ndarray, scalar: bool):
    return float(arr) if scalar else arr


def _t_in_range(t: float, t_C) -> None:
    if not math.isfinite(t):
        raise ValueError(f"t_C must be finite, got {t_C!r}")
    if t < T_MIN_C or t > T_MAX_C:
        raise ValueError(f"t_C out of type K range [{T_MIN_C}, {T_MAX_C}] °C: {t_C!r}")


def _emf_scalar(t: float) -> float:
    if t < 0.0:
        return _horner(_H["c_neg"], t)
    d = t - _A2
    return _horner(_H["c_pos"], t) + _A0 * float(np.exp(_A1 * (d * d)))


def _seebeck_scalar(t: float) -> float:
    if t < 0.0:
        return _horner(_H["dc_neg"], t) * 1e3
    d = t - _A2
    return (_horner(_H["dc_pos"], t) + _A0 * float(np.exp(_A1 * (d * d))) * 2.0 * _A1 * d) * 1e3


def emf_mV(t_C):
    """Type K EMF in mV for hot-junction temperature ``t_C`` (°C), reference at 0 °C.

    Valid for -270 °C <= t_C <= 1372 °C; raises ValueError outside.
    """
    x = _real_scalar(t_C)
    if x is not None:
        _t_in_range(x, t_C)
        return _emf_scalar(x)
    t, scalar = _as_array(t_C, "t_C")
    if np.any(t < T_MIN_C) or np.any(t > T_MAX_C):
        raise ValueError(f"t_C out of type K range [{T_MIN_C}, {T_MAX_C}] °C: {t_C!r}")
    neg = _polyval(_C_NEG, t)
    pos = _polyval(_C_POS, t) + _A0 * np.exp(_A1 * (t - _A2) ** 2)
    return _out(np.where(t < 0.0, neg, pos), scalar)


def seebeck_uV_per_K(t_C):
    """Seebeck coefficient dE/dT in µV/K at ``t_C`` (°C), from the reference function."""
    x = _real_scalar(t_C)
    if x is not None:
        _t_in_range(x, t_C)
        return _seebeck_scalar(x)
    t, scalar = _as_array(t_C, "t_C")
    if np.any(t < T_MIN_C) or np.any(t > T_MAX_C):
        raise ValueError(f"t_C out of type K range [{T_MIN_C}, {T_MAX_C}] °C: {t_C!r}")
    dneg = _polyval(_DC_NEG, t)
    dpos = (_polyval(_DC_POS, t)
            + _A0 * np.exp(_A1 * (t - _A2) ** 2) * 2.0 * _A1 * (t - _A2))
    return _out(np.where(t < 0.0, dneg, dpos) * 1e3, scalar)


def _temperature_scalar(e: float, e_mV, refine: bool) -> float:
    if not math.isfinite(e):
        raise ValueError(f"e_mV must be finite, got {e_mV!r}")
    if e < INVERSE_E_MIN_MV or e > E_MAX_MV:
        raise ValueError(
            f"e_mV out of type K inverse range [{INVERSE_E_MIN_MV}, {E_MAX_MV}] mV: {e_mV!r}")
    t = _horner(_H["d_neg"] if e < 0.0 else _H["d_mid"] if e < _E_SPLIT_MV else _H["d_high"], e)
    if refine:
        for _ in range(2):
            tc = min(max(t, T_MIN_C), T_MAX_C)
            t = tc - (_emf_scalar(tc) - e) / (_seebeck_scalar(tc) * 1e-3)
        t = min(max(t, T_MIN_C), T_MAX_C)
    return t


def temperature_C(e_mV, *, refine: bool = False):
    """Temperature (°C) for type K EMF ``e_mV`` (mV), reference junction at 0 °C.

    Uses the NIST inverse polynomials (valid -5.891 mV .. 54.886 mV, i.e.
    -200 °C .. 1372 °C; accuracy within ±0.06 °C). With ``refine=True`` two
    Newton steps on the reference function remove the inverse-polynomial error
    (useful when millikelvin *differences* matter, e.g. with a 24-bit ADC).
    """
    x = _real_scalar(e_mV)
    if x is not None:
        return _temperature_scalar(x, e_mV, refine)
    e, scalar = _as_array(e_mV, "e_mV")
    if np.any(e < INVERSE_E_MIN_MV) or np.any(e > E_MAX_MV):
        raise ValueError(
            f"e_mV out of type K inverse range [{INVERSE_E_MIN_MV}, {E_MAX_MV}] mV: {e_mV!r}")
    t = np.where(e < 0.0, _polyval(_D_NEG, e),
                 np.where(e < _E_SPLIT_MV, _polyval(_D_MID, e), _polyval(_D_HIGH, e)))
    if refine:
        for _ in range(2):
            tc = np.clip(t, T_MIN_C, T_MAX_C)
            t = tc - (np.asarray(emf_mV(tc)) - e) / (np.asarray(seebeck_uV_per_K(tc)) * 1e-3)
        t = np.clip(t, T_MIN_C, T_MAX_C)
    return _out(np.asarray(t, dtype=float), scalar)


def hot_junction_C(emf_measured_mV, cold_junction_C, *, refine: bool = False):
    """Cold-junction-compensated hot-junction temperature (°C).

    ``T_hot = T(E_meas + E(T_cj))``: the measured EMF is that of a thermocouple
    whose reference junction sits at ``cold_junction_C``; adding ``E(T_cj)``
    refers it to 0 °C before inverting.
    """
    em, cj = _real_scalar(emf_measured_mV), _real_scalar(cold_junction_C)
    if em is not None and cj is not None:
        if not math.isfinite(em):
            raise ValueError(f"emf_measured_mV must be finite, got {emf_measured_mV!r}")
        e_sum = em + emf_mV(cj)
        try:
            return _temperature_scalar(e_sum, e_sum, refine)
        except ValueError as exc:
            raise ValueError(
                f"emf_measured_mV + E(cold_junction_C) outside the type K inverse range: {exc}") from None
    e_meas, _ = _as_array(emf_measured_mV, "emf_measured_mV")
    e_total = e_meas + np.asarray(emf_mV(cold_junction_C))
    scalar = np.ndim(emf_measured_mV) == 0 and np.ndim(cold_junction_C) == 0
    try:
        t = temperature_C(e_total, refine=refine)
    except ValueError as exc:
        raise ValueError(
            f"emf_measured_mV + E(cold_junction_C) outside the type K inverse range: {exc}") from None
    return float(t) if scalar else np.asarray(t)
