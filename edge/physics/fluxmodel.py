"""The flux-driven model: object surface temperature from a surface heat flux.

Paper eqs. (12)-(13): with the measured flux q_f(t) as the boundary condition
the object alone determines T_f(t).  Three ways to compute it:

``"duhamel"`` (semi-infinite objects)
    T(t) = 1/(e sqrt(pi)) * integral_0^t q(s) / sqrt(t - s) ds, with
    e = k / sqrt(alpha) the effusivity, integrated exactly for q linear
    between samples.  T depends on k and alpha only through e, which is why
    one touch on a thick object determines e and nothing more.  On a uniform
    grid the operator is lower-triangular Toeplitz but for its first column:
    it is applied as an O(n) kernel and an FFT product (:func:`duhamel_apply`),
    never formed.
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
from functools import lru_cache

import numpy as np

from edge.checks import finite_array, finite_positive, one_of, strictly_increasing
from edge.physics import fvm
from edge.physics.integrators import ModalSolver, _phi, _uniform_from_zero, causal_convolution, explicit_march
from edge.physics.schedule import PowerSchedule
from edge.physics.solids import Solid

FLUX_SCHEMES = ("duhamel", "default", "paper")



def _flux_record(t_s, q_W_m2, thickness_m, back: str) -> tuple[np.ndarray, np.ndarray]:
    """Checked (t, q) of a flux record and its object: one statement of what every flux model demands."""
    one_of("back", back, fvm.BACKS)
    t = finite_array("t_s", t_s, min_len=2)
    strictly_increasing("t_s", t)
    q = finite_array("q_W_m2", q_W_m2)
    if q.shape != t.shape:
        raise ValueError(f"q_W_m2 has {q.size} samples but t_s has {t.size}")
    if back != "infinite":
        finite_positive("thickness_m", thickness_m)
    return t, q

def duhamel_matrix(t_s: np.ndarray) -> np.ndarray:
    """Matrix D with T(t_i) = (D @ q)_i / e for q linear between the samples.

    ``t_s`` starts at the onset of the flux (t_s[0], usually 0); D already
    carries the factor 1/sqrt(pi).  Units: K per (W/m^2) times W s^0.5/m^2/K.
    Dense, O(n^2) in time and memory: for T itself use :func:`duhamel_apply`.
    """
    t = finite_array("t_s", t_s)
    strictly_increasing("t_s", t)
    n = t.size
    dt = _uniform_from_zero(t - t[0])
    if dt is None:
        return _duhamel_rows(t, 0, n)
    col, first = duhamel_kernel(n, dt)
    i = np.arange(n)
    k = i[:, None] - i[None, :]
    D = np.where(k >= 0, col[np.clip(k, 0, None)], 0.0)
    D[:, 0] = first
    return D


#: Rows of the dense operator built at a time on non-uniform grids (memory O(block n)).
_ROW_BLOCK = 256


def _interval_weights(u: np.ndarray, s: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weights of an interval's left and right samples in the integral of q / sqrt(t_i - tau).

    For the interval [t_j, t_j+1] of length h, q linear in tau, u = sqrt(t_i - t_j)
    and s = sqrt(t_i - t_j+1): (2/3) h (u + 2s) / (u + s)^2 and (2/3) h (2u + s) / (u + s)^2,
    the cancellation-free form of (-a I0 + I1) / h and (b I0 - I1) / h.
    """
    w = (2.0 / 3.0) * h / (u + s) ** 2
    return w * (u + 2.0 * s), w * (2.0 * u + s)


def _duhamel_rows(t: np.ndarray, i0: int, i1: int) -> np.ndarray:
    """Rows i0:i1 of D on any increasing grid ``t`` (starting at the flux onset)."""
    h = np.diff(t)
    ti = t[i0:i1, None]
    active = ti > t[None, :-1]  # interval j lies before t_i
    u = np.sqrt(np.clip(ti - t[None, :-1], 0.0, None))
    s = np.sqrt(np.clip(ti - t[None, 1:], 0.0, None))
    with np.errstate(divide="ignore", invalid="ignore"):
        w_left, w_right = _interval_weights(u, s, h[None, :])
    D = np.zeros((i1 - i0, t.size))
    D[:, :-1] += np.where(active, w_left, 0.0)
    D[:, 1:] += np.where(active, w_right, 0.0)
    return D / math.sqrt(math.pi)


def duhamel_kernel(n: int, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The Duhamel operator on the uniform grid t_i = i dt_s as two length-n vectors.

    D is lower-triangular Toeplitz but for its first column: D[i, j] =
    col[i - j] for 1 <= j <= i, D[i, 0] = first[i] (the first sample has no
    interval before it), zero above the diagonal.  O(n) time and memory.
    """
    k = np.arange(n, dtype=np.float64)
    # Interval m (m >= 1) ends m steps before t_i: u = sqrt(m dt), s = sqrt((m - 1) dt).
    m = k[1:]
    h = np.full(m.size, float(dt_s))
    w_left, w_right = _interval_weights(np.sqrt(m * dt_s), np.sqrt((m - 1.0) * dt_s), h)
    first = np.concatenate(([0.0], w_left))
    col = first.copy()
    col[:-1] += w_right  # the sample's right weight in the interval after it
    scale = 1.0 / math.sqrt(math.pi)
    return col * scale, first * scale


def _fft_size(n: int) -> int:
    """Smallest 2^a 3^b 5^c >= n (sizes pocketfft transforms fastest)."""
    best = 1 << max(0, (n - 1).bit_length())
    p5 = 1
    while p5 < best:
        p35 = p5
        while p35 < best:
            p = p35
            while p < n:
                p *= 2
            best = min(best, p)
            p35 *= 3
        p5 *= 5
    return best


@lru_cache(maxsize=4)
def _duhamel_spectrum(n: int, dt_s: float) -> tuple[np.ndarray, np.ndarray, int]:
    """rfft of the Toeplitz column, the first-column correction and the FFT size (O(n) each)."""
    col, first = duhamel_kernel(n, dt_s)
    size = _fft_size(2 * n - 1)
    spec = np.fft.rfft(col, size)
    spec.flags.writeable = False
    fix = first - col
    fix.flags.writeable = False
    return spec, fix, size


def duhamel_apply(q_W_m2, dt_s: float) -> np.ndarray:
    """D @ q on the uniform grid t_i = i dt_s, without forming D: O(n log n), memory O(n).

    ``q_W_m2`` is (n,) or (n, m) (m series at once); the result has its
    shape and the units of q times s^0.5 (divide by e for kelvin).
    """
    q = np.asarray(q_W_m2, dtype=np.float64)
    n = q.shape[0]
    spec, fix, size = _duhamel_spectrum(n, float(dt_s))
    q2 = q.reshape(n, -1)
    out = np.fft.irfft(np.fft.rfft(q2, size, axis=0) * spec[:, None], size, axis=0)[:n]
    out += fix[:, None] * q2[0]
    return out.reshape(q.shape)


def _duhamel_apply_rows(t: np.ndarray, q: np.ndarray) -> np.ndarray:
    """D @ q on a non-uniform grid, a block of rows at a time (O(n^2) time, O(n) memory)."""
    out = np.empty(t.size)
    for i0 in range(0, t.size, _ROW_BLOCK):
        i1 = min(t.size, i0 + _ROW_BLOCK)
        out[i0:i1] = _duhamel_rows(t, i0, i1) @ q
    return out


def surface_temperature_scan(t_s, q_W_m2, solids, *, thickness_m: float | None = None,
                             back: str = "infinite") -> np.ndarray:
    """``surface_temperature(t_s, q_W_m2, s, ..., scheme="default")`` for every s in ``solids``, as rows (K).

    One pass over the scan: on a uniform ``t_s`` each solid's grid
    contributes its response to a unit ramp (O(modes n), see
    :meth:`ModalSolver.march_linear`) and all of them are convolved with
    the flux's slope changes in one FFT product.
    """
    t, q = _flux_record(t_s, q_W_m2, thickness_m, back)
    tt = t - t[0]
    dt = _uniform_from_zero(tt)
    if dt is None:
        return np.array([surface_temperature(t, q, s, thickness_m=thickness_m, back=back, scheme="default")
                         for s in solids]).reshape(len(solids), t.size)
    n = t.size
    duration = float(tt[-1])
    dslope = np.diff(np.concatenate(([0.0], np.diff(q) / np.diff(tt))))
    ramps = np.empty((len(solids), n))
    out = np.zeros((len(solids), n))
    for i, solid in enumerate(solids):
        grid = fvm.object_grid(solid, duration_s=duration, t_first_s=float(tt[1]), thickness_m=thickness_m, back=back)
        ms = ModalSolver(grid)
        r_T = np.zeros(grid.n)
        r_T[0] = 1.0
        mrows = ms.rows_to_modal(r_T)
        ramps[i] = ms.ramp_response(mrows, dt, n)[0]
        if q[0] != 0.0:
            out[i] = (mrows @ (ms.beta[:, None] * _phi(ms.lam[:, None], tt[None, :])))[0] * q[0]
    out += causal_convolution(ramps, dslope)
    return out


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
    t, q = _flux_record(t_s, q_W_m2, thickness_m, back)
    tt = t - t[0]
    if scheme == "duhamel":
        if back != "infinite":
            raise ValueError("scheme='duhamel' is exact only for back='infinite'; use scheme='default'")
        dt = _uniform_from_zero(tt)
        Dq = _duhamel_apply_rows(tt, q) if dt is None else duhamel_apply(q, dt)
        return Dq / solid.effusivity_W_s05_m2K
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
