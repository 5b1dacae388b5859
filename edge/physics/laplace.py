"""Exact solution of the layered probe model in the Laplace domain.

The probe (heater layer with uniform source on top of the sensing layer, same
material, insulated top) on the object is solved exactly in s with thermal
quadrupoles and inverted numerically with the fixed-Talbot method
(Abate & Valko 2004).  No spatial or temporal grid is involved, so this is
the reference the grid schemes are measured against, and the simulator's
"truth".  Optional thermal contact resistance between probe and object.

Only ratios of hyperbolic functions are formed (tanh, sech), so large
arguments do not overflow.
"""

from __future__ import annotations

import numpy as np

from edge.checks import finite_array, finite_nonnegative, one_of
from edge.physics.memo import BoundedMemo
from edge.physics.probe import ProbeStack
from edge.physics.solids import Solid

_M_TALBOT = 24


def _tanh(z: np.ndarray) -> np.ndarray:
    # tanh(z) for Re z >= 0 without overflow: (1 - e^{-2z}) / (1 + e^{-2z}).
    e = np.exp(-2.0 * z)
    return (1.0 - e) / (1.0 + e)


def _sech(z: np.ndarray) -> np.ndarray:
    e = np.exp(-z)
    return 2.0 * e / (1.0 + e * e)


def object_admittance(s: np.ndarray, solid: Solid, thickness_m: float | None, back: str) -> np.ndarray:
    """Laplace-domain surface admittance q/T of the object (W/m^2/K)."""
    m = np.sqrt(s / solid.alpha_m2_s)
    km = solid.k_W_mK * m
    if back == "infinite" or thickness_m is None:
        return km
    t = _tanh(m * thickness_m)
    return km / t if back == "fixed" else km * t


def probe_transfer(
    s: np.ndarray,
    solid: Solid,
    stack: ProbeStack,
    thickness_m: float | None,
    back: str,
    contact_resistance_m2K_W: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Transforms of T_f and q_f for a unit step of q_v (1 W/m^3 from t = 0).

    T_f is the temperature at the bottom of the sensing layer (where the
    thermocouple sits); with a contact resistance the object surface is
    cooler by R q_f.
    """
    p = stack.material
    a = np.sqrt(s / p.alpha_m2_s)
    ka = p.k_W_mK * a
    Y = object_admittance(s, solid, thickness_m, back)
    if contact_resistance_m2K_W > 0.0:
        Y = Y / (1.0 + contact_resistance_m2K_W * Y)
    t_s = _tanh(a * stack.sensing_thickness_m)
    t_h = _tanh(a * stack.heater_thickness_m)
    Y1 = ka * (ka * t_s + Y) / (ka + t_s * Y)
    P = 1.0 / (p.rho_c_J_m3K * s * s)
    theta_1 = P * ka * t_h / (ka * t_h + Y1)
    theta_f = theta_1 * _sech(a * stack.sensing_thickness_m) / (1.0 + t_s * Y / ka)
    return theta_f, Y * theta_f


#: Contours already built, by M and the times' bytes: the nodes and weights depend on the times only, and a
#: fit inverts one grid's kernels for every trial of its parameters (the sensor chain's slab kernels).
_CONTOURS = BoundedMemo(4)


def _talbot_contour(t: np.ndarray, M: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(r, s, gamma) of the fixed Talbot contour at times ``t``: nodes s (n_t, M) and weights gamma (read-only)."""
    return _CONTOURS((M, t.shape, t.tobytes()), lambda: _contour(t, M))


def _contour(t: np.ndarray, M: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_talbot_contour`, computed."""
    k = np.arange(1, M)
    theta = k * np.pi / M
    cot = 1.0 / np.tan(theta)
    r = 2.0 * M / (5.0 * t)  # (n_t,)
    s = np.empty((t.size, M), dtype=complex)
    s[:, 0] = r
    s[:, 1:] = r[:, None] * theta * (cot + 1j)
    sigma = theta + (theta * cot - 1.0) * cot
    gamma = np.empty((t.size, M), dtype=complex)
    gamma[:, 0] = 0.5 * np.exp(r * t)
    gamma[:, 1:] = np.exp(t[:, None] * s[:, 1:]) * (1.0 + 1j * sigma)
    return r, s, gamma


def talbot_invert(F, t_s: np.ndarray, M: int = _M_TALBOT) -> np.ndarray:
    """Inverse Laplace transform of ``F`` at times ``t_s`` > 0 (fixed Talbot).

    ``F`` maps a complex array of s values to an array of the same shape
    (or a tuple of them, inverted together).
    """
    t = np.asarray(t_s, dtype=float)
    r, s, gamma = _talbot_contour(t, M)
    vals = F(s)
    single = not isinstance(vals, tuple)
    if single:
        vals = (vals,)
    out = tuple((r / M) * np.real(np.sum(gamma * v, axis=1)) for v in vals)
    return out[0] if single else out


def probe_step_response(
    solid: Solid,
    t_s: np.ndarray,
    *,
    stack: ProbeStack,
    thickness_m: float | None = 0.04,
    back: str = "fixed",
    contact_resistance_m2K_W: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Exact T_f (K) and q_f (W/m^2) at ``t_s`` for a unit step of q_v (W/m^3)."""
    one_of("back", back, ("fixed", "insulated", "infinite"))
    finite_nonnegative("contact_resistance_m2K_W", contact_resistance_m2K_W)
    t = finite_array("t_s", t_s)
    T = np.zeros(t.size)
    q = np.zeros(t.size)
    pos = t > 0
    if pos.any():
        T[pos], q[pos] = talbot_invert(
            lambda s: probe_transfer(s, solid, stack, thickness_m, back, contact_resistance_m2K_W), t[pos]
        )
    return T, q
