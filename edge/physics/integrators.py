"""Time integration of ``C dT/dt = -K T + s q_v(t)`` on a :class:`~edge.physics.fvm.Grid`.

* :class:`ModalSolver` - exact in time for piecewise-constant q_v: the system
  is symmetrised with C^(-1/2), diagonalised once, and each mode is advanced
  with its exact exponential.  Unconditionally stable, any step, any output
  times; one eigendecomposition serves every power level.
* :func:`explicit_march` - forward Euler (FTCS), the paper's scheme, with the
  step chosen automatically from every cell's own stability limit
  ``dt <= C_i / (G_{i-1} + G_i)`` (which is ``dx^2 / (2 alpha)`` inside a layer
  and tighter at the heater and interface cells).  It refuses, with a
  ValueError, runs that would need more than ``max_steps``.

Both return the observed outputs at the requested times and the energy
account (released, stored, conducted out through a fixed back), all per unit
area, so callers can check that the balance closes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from edge.physics.fvm import Grid
from edge.physics.schedule import PowerSchedule


@dataclass(frozen=True)
class March:
    """Outputs of a time march.

    ``outputs`` has one row per observation row given, one column per output
    time.  Energies are in J/m^2 at the final time.
    """

    outputs: np.ndarray
    released_J_m2: float
    stored_J_m2: float
    conducted_out_J_m2: float
    n_steps: int


def _event_times(t_out: np.ndarray, schedule: PowerSchedule) -> tuple[np.ndarray, np.ndarray]:
    """Sorted union of output times and switching times; mask of the output ones."""
    sw = schedule.t_start_s[schedule.t_start_s < t_out[-1]]
    times = np.union1d(t_out, sw)
    times = times[times > 0.0]
    is_out = np.isin(times, t_out)
    return times, is_out


def _phi(lam: np.ndarray, h) -> np.ndarray:
    """(1 - exp(-lam h)) / lam, with its limit h at lam -> 0 (broadcasts)."""
    lam, h = np.broadcast_arrays(lam, h)
    x = lam * h
    small = x < 1e-8
    with np.errstate(divide="ignore", invalid="ignore"):
        big = -np.expm1(-x) / lam
    return np.where(small, h * (1.0 - 0.5 * x), big)


def _psi(lam: np.ndarray, h) -> np.ndarray:
    """(h - phi(lam, h)) / lam = integral over [0, h] of phi(lam, t) dt (broadcasts)."""
    lam, h = np.broadcast_arrays(lam, h)
    x = lam * h
    small = x < 1e-4
    with np.errstate(divide="ignore", invalid="ignore"):
        big = (h + np.expm1(-x) / lam) / lam
    return np.where(small, h * h * (0.5 - x / 6.0 + x * x / 24.0), big)


class ModalSolver:
    """Exact-in-time solver for one grid (see module docstring).

    Parameters
    ----------
    grid : Grid
        The assembled grid.
    """

    def __init__(self, grid: Grid) -> None:
        self.grid = grid
        d = 1.0 / np.sqrt(grid.C)
        n = grid.n
        G = grid.G
        diag = G.copy()
        diag[1:] += G[:-1]
        A = np.diag(diag * d * d)
        off = -G[:-1] * d[:-1] * d[1:]
        A[np.arange(n - 1), np.arange(1, n)] = off
        A[np.arange(1, n), np.arange(n - 1)] = off
        lam, V = np.linalg.eigh(A)
        # K is positive semi-definite; round-off can leave -eps eigenvalues.
        self.lam = np.clip(lam, 0.0, None)
        self.V = V
        self._d = d
        self.beta = V.T @ (d * grid.source)
        self._stored_row = (grid.C * d) @ V
        self._out_row = (G[-1] * d[-1]) * V[-1]

    def rows_to_modal(self, rows: np.ndarray) -> np.ndarray:
        """Map observation rows on temperatures to rows on modal coordinates."""
        return (np.atleast_2d(rows) * self._d) @ self.V

    def march(self, schedule: PowerSchedule, t_out: np.ndarray, rows: np.ndarray) -> March:
        """Outputs ``rows @ T`` at ``t_out`` (s, increasing, >= 0) under ``schedule``.

        Each switch of q_v starts a step whose modal response is exact,
        ``beta * (1 - exp(-lam t)) / lam``; the outputs are their sum.
        """
        mrows = self.rows_to_modal(rows)
        lam, beta = self.lam, self.beta
        t_end = float(t_out[-1])
        dq = np.diff(np.concatenate(([0.0], schedule.q_v_W_m3)))
        outputs = np.zeros((mrows.shape[0], t_out.size))
        z_end = np.zeros_like(lam)
        out_int = 0.0
        n_switch = 0
        for t0, d in zip(schedule.t_start_s, dq):
            if d == 0.0 or t0 >= t_end:
                continue
            n_switch += 1
            m = t_out > t0
            tau = t_out[m] - t0
            outputs[:, m] += d * (mrows @ (beta[:, None] * _phi(lam[:, None], tau[None, :])))
            z_end += d * beta * _phi(lam, t_end - t0)
            out_int += d * float(self._out_row @ (beta * _psi(lam, t_end - t0)))
        return March(
            outputs=outputs,
            released_J_m2=schedule.energy_density(t_end) * float(self.grid.source.sum()),
            stored_J_m2=float(self._stored_row @ z_end),
            conducted_out_J_m2=out_int,
            n_steps=n_switch,
        )


    def march_linear(self, t_knots: np.ndarray, u_knots: np.ndarray, t_out: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """Outputs ``rows @ T`` at ``t_out`` for a piecewise-linear drive.

        ``u`` interpolates ``u_knots`` linearly between ``t_knots`` (the first
        knot is t = 0) and holds its last slope beyond the last knot.  Exact:
        the drive is a step plus ramps, and a ramp's modal response is
        ``beta * psi(lam, t)``.
        """
        mrows = self.rows_to_modal(rows)
        lam, beta = self.lam, self.beta
        slopes = np.diff(u_knots) / np.diff(t_knots)
        dslope = np.diff(np.concatenate(([0.0], slopes)))
        if u_knots[0] == 0.0:  # the usual start from rest: no step term
            outputs = np.zeros((mrows.shape[0], t_out.size))
        else:
            outputs = (mrows @ (beta[:, None] * _phi(lam[:, None], t_out[None, :]))) * u_knots[0]
        dt = _uniform_from_zero(t_knots)
        if dt is not None and t_out.shape == t_knots.shape and np.array_equal(t_out, t_knots):
            # Knots are the outputs on a uniform grid: the ramp started at knot j
            # reaches output i after (i - j) steps, so the sum over knots is a
            # causal convolution of dslope with one ramp response g.
            outputs += causal_convolution(self.ramp_response(mrows, dt, t_out.size), dslope)
            return outputs
        for t0, d in zip(t_knots[:-1], dslope):
            if d == 0.0:
                continue
            m = t_out > t0
            tau = t_out[m] - t0
            outputs[:, m] += d * (mrows @ (beta[:, None] * _psi(lam[:, None], tau[None, :])))
        return outputs

    def ramp_response(self, mrows: np.ndarray, dt: float, n: int) -> np.ndarray:
        """g[:, k] = mrows @ (beta * psi(lam, k dt)), k = 0 .. n-1: the outputs' response to a unit ramp.

        psi(lam, t) = t / lam + expm1(-lam t) / lam^2 (for lam t >= 1e-4).
        The slowest modes (lam dt < 1e-2, near the series branch) go through
        :func:`_psi` point by point.  For the others the t / lam terms sum to a
        line and the expm1 terms are summed as matrix products; expm1(-lam t)
        is -1 in floating point once lam t > 40, so a mode needs it only for
        its first 40 / (lam dt) steps (modes are banded by that length).
        """
        lam = self.lam
        w = mrows * self.beta
        tau = dt * np.arange(n)
        x1 = lam * dt
        slow = x1 < 1e-2
        g = w[:, slow] @ _psi(lam[slow, None], tau[None, :])
        if slow.all():
            return g
        rest = ~slow
        lr, wr = lam[rest], w[:, rest]
        inv = 1.0 / lr
        g += (wr @ inv)[:, None] * tau
        c = wr * (inv * inv)  # weights of expm1(-lam t)
        steps = np.minimum(np.ceil(40.0 / x1[rest]), n)  # expm1 = -1 from here on
        lo = 1
        for hi in (2, 33, n + 1):  # bands: none (fast modes), up to 32 steps, the rest
            band = (steps >= lo) & (steps < hi)
            lo = hi
            if not band.any():
                continue
            k = int(min(n, hi - 1))
            cb = c[:, band]
            g[:, :k] += cb @ np.expm1(np.multiply.outer(-lr[band], tau[:k]))
            if k < n:
                g[:, k:] -= cb.sum(axis=1)[:, None]
            if lo > n:
                break
        return g


def _uniform_from_zero(t: np.ndarray) -> float | None:
    """The step dt if ``t`` is i * dt (i = 0 .. n-1) to rounding, else None."""
    n = t.size
    if n < 2 or t[0] != 0.0:
        return None
    dt = float(t[-1]) / (n - 1)
    tol = 16.0 * np.finfo(float).eps * abs(float(t[-1]))
    return dt if dt > 0 and float(np.max(np.abs(t - dt * np.arange(n)))) <= tol else None


#: Kernels up to this many samples are convolved directly (np.convolve), longer ones through the FFT.
_DIRECT_MAX = 512


def _fft_size(n: int) -> int:
    """The FFT length of a causal convolution of ``n`` samples: a power of two >= 2n - 1 (no wrap-around)."""
    return 1 << (2 * n - 1).bit_length()


def causal_convolution(g: np.ndarray, d: np.ndarray) -> np.ndarray:
    """out[..., i] = sum over j <= i of g[..., i - j] d[j], for i < g.shape[-1] (FFT when long)."""
    n = g.shape[-1]
    d = d[:n]
    if n <= _DIRECT_MAX and g.size <= 4 * n:
        if g.ndim == 1:   # one kernel (the sensor chain's many small calls): no stacking round trip
            return np.convolve(g, d)[:n]
        return np.stack([np.convolve(row, d)[:n] for row in np.atleast_2d(g)]).reshape(g.shape)
    size = _fft_size(n)
    return np.fft.irfft(np.fft.rfft(g, size) * np.fft.rfft(d, size), size)[..., :n]


def causal_convolution_columns(g: np.ndarray, D: np.ndarray) -> np.ndarray:
    """``causal_convolution(g, D[:, j])`` for every column j of ``D`` (n, m), one kernel ``g`` (n,).

    The same numbers as the calls one by one (the same arithmetic per column), with the kernel's
    transform taken once instead of once per column: the sensor chain lags three columns through one
    bead kernel on every design a calibration builds (:func:`edge.estimation.sensor_chain._lag`).
    """
    n = g.shape[-1]
    D = D[:n]
    if n <= _DIRECT_MAX:   # causal_convolution's direct branch for one kernel
        return np.column_stack([np.convolve(g, D[:, j])[:n] for j in range(D.shape[1])])
    size = _fft_size(n)
    G = np.fft.rfft(g, size)
    return np.column_stack([np.fft.irfft(G * np.fft.rfft(D[:, j], size), size)[:n] for j in range(D.shape[1])])


def explicit_dt_max(grid: Grid) -> float:
    """Largest stable forward-Euler step: min over cells of C_i / (G_{i-1} + G_i) (s)."""
    g_sum = grid.G.copy()
    g_sum[1:] += grid.G[:-1]
    return float(np.min(grid.C / g_sum))


def explicit_march(
    grid: Grid,
    schedule: PowerSchedule,
    t_out: np.ndarray,
    rows: np.ndarray,
    *,
    max_steps: int = 3_000_000,
) -> March:
    """Forward-Euler march with an automatically chosen stable step.

    Between consecutive event times (outputs and switching times) the step is
    the largest equal subdivision not exceeding the stability limit.

    Raises
    ------
    ValueError
        If the run would need more than ``max_steps`` steps.
    """
    rows = np.atleast_2d(rows)
    dt_max = explicit_dt_max(grid)
    times, is_out = _event_times(t_out, schedule)
    spans = np.diff(np.concatenate(([0.0], times)))
    n_sub = np.maximum(1, np.ceil(spans / dt_max * (1.0 + 1e-12)).astype(np.int64))
    total = int(n_sub.sum())
    if total > max_steps:
        raise ValueError(
            f"explicit scheme needs {total} time steps (stable step {dt_max:.3g} s) "
            f"> max_steps={max_steps}; use scheme='default' or a coarser grid"
        )
    C, G, src = grid.C, grid.G, grid.source
    n = grid.n
    # Padded buffers make every step six whole-array ufunc calls (the step is a few
    # microseconds of call overhead on ~1000 cells, and runs take ~1e5 steps):
    # T_pad[n] is the held back's 0 K excess, so flux = G (T_pad[:-1] - T_pad[1:]) includes
    # the back's g_back T[-1]; flux_pad[0] = 0 is the (absent) flux into the top cell.
    T_pad = np.zeros(n + 1)
    T = T_pad[:-1]
    T_below = T_pad[1:]  # T_below[i] = T[i+1]
    flux_pad = np.zeros(n + 1)
    flux = flux_pad[1:]  # flux[i]: from node i to node i+1 (or to the fixed back)
    flux_in = flux_pad[:-1]  # flux_in[i] = flux[i-1]: into node i from above
    dT = np.zeros(n)
    inv_C = 1.0 / C
    outputs = np.zeros((rows.shape[0], t_out.size))
    k_out = int(np.count_nonzero(t_out <= 0.0))
    stored_out = 0.0
    sub, mul, add = np.subtract, np.multiply, np.add
    t_prev = 0.0
    for t, keep, m in zip(times, is_out, n_sub):
        dt = (t - t_prev) / m
        q = float(schedule.value_at(t_prev))
        heat = src * q
        coef = dt * inv_C
        for _ in range(m):
            sub(T, T_below, out=flux)
            mul(flux, G, out=flux)
            stored_out += dt * flux[-1]
            sub(heat, flux, out=dT)
            add(dT, flux_in, out=dT)
            mul(dT, coef, out=dT)
            add(T, dT, out=T)
        if keep:
            outputs[:, k_out] = rows @ T
            k_out += 1
        t_prev = t
    return March(
        outputs=outputs,
        released_J_m2=schedule.energy_density(t_out[-1]) * float(src.sum()),
        stored_J_m2=float(C @ T),
        conducted_out_J_m2=stored_out,
        n_steps=total,
    )
