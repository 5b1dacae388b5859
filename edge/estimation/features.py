"""The paper's signal features u1-u8 (Ma & Zhang 2024, section 3.2).

For a record (t, q_f, T_f) on a uniform time grid starting at heater-on:

====  ==================================================================
u1    least-squares slope of the flux relative to its initial value,
      d(q - q[0])/dt  (W/m^2/s)
u2    least-squares slope of the excess temperature, dT/dt  (K/s)
u3    mean flux  (W/m^2)
u4    mean excess temperature  (K)
u5    excess temperature at the final time  (K)
u6    excess temperature at the midpoint time  (K)
u7    u5 - u6, temperature rise from midpoint to final time  (K)
u8    flux difference q(final) - q(initial)  (W/m^2)
====  ==================================================================

u8's text ("the difference in heat flux") is ambiguous; the PCA loadings of
the paper's eq. (11) group x8 with the flux features x1 and x3, which the
final-minus-initial difference does, so that is the reading taken here.

Logarithm of features that can be negative
-------------------------------------------
All eight are positive for a heated contact, but noise can push a small one
(u1 on a metal, u7 on a foam) through zero.  Each feature is clipped from
below at a floor fixed at training time (1e-3 of its smallest training
value) before ln; a clip is reported so the estimate can be flagged.  A
signed log was rejected because it maps small negative noise far from the
small positive values the network was trained on.
"""

from __future__ import annotations

import numpy as np

FEATURE_VERSION = 1
N_FEATURES = 8


def paper_features(t_s: np.ndarray, q_W_m2: np.ndarray, T_K: np.ndarray) -> np.ndarray:
    """u1..u8 for one record or a batch.

    Parameters
    ----------
    t_s : (n,) sample times (s), uniform, starting at heater-on.
    q_W_m2, T_K : (n,) or (batch, n) flux into the object and excess temperature.

    Returns
    -------
    (8,) or (batch, 8) features in the units listed in the module docstring.
    """
    t = np.asarray(t_s, dtype=float)
    q = np.atleast_2d(np.asarray(q_W_m2, dtype=float))
    T = np.atleast_2d(np.asarray(T_K, dtype=float))
    if q.shape != T.shape or q.shape[-1] != t.size:
        raise ValueError(f"q_W_m2 {q.shape} and T_K {T.shape} must both have {t.size} samples")
    tc = t - t.mean()
    denom = float(tc @ tc)
    mid = t.size // 2
    u = np.empty((q.shape[0], N_FEATURES))
    u[:, 0] = ((q - q[:, :1]) @ tc) / denom
    u[:, 1] = (T @ tc) / denom
    u[:, 2] = q.mean(axis=1)
    u[:, 3] = T.mean(axis=1)
    u[:, 4] = T[:, -1]
    u[:, 5] = T[:, mid]
    u[:, 6] = T[:, -1] - T[:, mid]
    u[:, 7] = q[:, -1] - q[:, 0]
    return u[0] if np.ndim(q_W_m2) == 1 else u


def log_features(u: np.ndarray, floor: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """ln(max(u, floor)) and a mask of the clipped entries."""
    clipped = u < floor
    return np.log(np.maximum(u, floor)), clipped
