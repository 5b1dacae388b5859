"""The flux-driven model: object surface temperature from a surface heat flux.

Paper eqs. (12)-(13): with the measured flux q_f(t) as the boundary condition
the object alone determines T_f(t).  Three ways to compute it:

``"duhamel"`` (semi-infinite objects)
    T(t) = 1/(e sqrt(pi)) * integral_0^t q(s) / sqrt(t - s) ds, with
    e = k / sqrt(alpha) the effusivity, integrated exactly for q linear
    between samples.  T depends on k and alpha only through e, which is why
    one touch on a thick object determines e and nothing more.
``"default"``
    Graded finite-volume grid sized to the penetration depth (or the
    object's thickness and back boundary), exact in time for a flux linear
    between samples.
``"paper"``
    Eq. (12) as written: explicit FTCS on a uniform 40 um grid to 40 mm with
    the far node held at T0, stable step chosen automatically, the flux held
    constant over each sample interval.
"""

from __future__ import annotations

import math

import numpy as np

from edge.physics import fvm
from edge.checks import finite_array, finite_positive, one_of, strictly_increasing
from edge.physics.integrators import ModalSolver, explicit_march
from edge.physics.schedule import PowerSchedule
from edge.physics.solids import Solid

FLUX_SCHEMES = ("duhamel", "default", "paper")


def duhamel_matrix(t_s: np.ndarray) -> np.ndarray:
    """Matrix D with T(t_i) = (D @ q)_i / e for q linear between the samples.

    ``t_s`` starts at the onset of the flux (t_s[0], usually 0); D already
    carries the factor 1/sqrt(pi).  Units: K per (W/m^2) times W s^0.5/m^2/K.
    """
    t = finite_array("t_s", t_s)
    strictly_increasing("t_s", t)
    n = t.size
    h = np.diff(t)
    ti = t[:, None]
    a = np.clip(ti - t[None, 1:], 0.0, None)  # t_i - t_{j+1}
    b = np.clip(ti - t[None, :-1], 0.0, None)  # t_i - t_j
    active = (ti > t[None, :-1])  # interval j lies before t_i
    i0 = 2.0 * (np.sqrt(b) - np.sqrt(a))
    i1 = (2.0 / 3.0) * (b ** 1.5 - a ** 1.5)
    w_left = np.where(active, (-a * i0 + i1) / h, 0.0)
    w_right = np.where(active, (b * i0 - i1) / h, 0.0)
    D = np.zeros((n, n))
    D[:, :-1] += w_left
    D[:, 1:] += w_right
    return D / math.sqrt(math.pi)


def surface_temperature(
    t_s,
    q_W_m2,
    solid: Solid,
    *,
    thickness_m: float | None = None,
    back: str = "infinite",
    scheme: str = "duhamel",
    dx_m: float = 40e-6,
    max_steps: int = 3_000_000,
) -> np.ndarray:
    """Excess surface temperature (K) at ``t_s`` for a surface flux ``q_W_m2`` (W/m^2).

    Parameters
    ----------
    t_s : (n,) increasing sample times (s); the flux starts at ``t_s[0]``.
    q_W_m2 : (n,) flux into the object at those times (W/m^2).
    solid : Solid
        Object properties (only k and alpha matter).
    thickness_m, back : object thickness and back boundary (``"fixed"``,
        ``"insulated"`` or ``"infinite"``); Duhamel needs ``"infinite"``.
    scheme : ``"duhamel"``, ``"default"`` or ``"paper"``.
    """
    one_of("scheme", scheme, FLUX_SCHEMES)
    one_of("back", back, fvm.BACKS)
    t = finite_array("t_s", t_s, min_len=2)
    strictly_increasing("t_s", t)
    q = finite_array("q_W_m2", q_W_m2)
    if q.shape != t.shape:
        raise ValueError(f"q_W_m2 has {q.size} samples but t_s has {t.size}")
    if back != "infinite":
        finite_positive("thickness_m", thickness_m)
    tt = t - t[0]
    if scheme == "duhamel":
        if back != "infinite":
            raise ValueError("scheme='duhamel' is exact only for back='infinite'; use scheme='default'")
        return duhamel_matrix(tt) @ q / solid.effusivity_W_s05_m2K
    duration = float(tt[-1])
    if scheme == "default":
        grid = fvm.object_grid(
            solid, duration_s=duration, t_first_s=float(tt[1]), thickness_m=thickness_m, back=back
        )
        r_T = np.zeros(grid.n)
        r_T[0] = 1.0
        return ModalSolver(grid).march_linear(tt, q, tt, r_T)[0]
    # The paper's eq. (12): 40 mm deep, far node at T0, unless the scene says otherwise.
    if back == "infinite":
        depth = max(0.04, 6.0 * math.sqrt(solid.alpha_m2_s * duration))
        end = "fixed"
    else:
        depth, end = thickness_m, back
    grid = fvm.object_grid(
        solid, duration_s=duration, t_first_s=float(tt[1]), thickness_m=depth, back=end, dx_m=dx_m
    )
    r_T = np.zeros(grid.n)
    r_T[0] = 1.0
    drive = PowerSchedule(tt[:-1], q[:-1], signed=True)
    return explicit_march(grid, drive, tt, r_T, max_steps=max_steps).outputs[0]
