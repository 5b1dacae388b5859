"""Flux-driven model (paper eqs. 12-13) against Duhamel's integral."""

import math

import numpy as np
import pytest

from edge.physics.fluxmodel import duhamel_matrix, surface_temperature
from edge.physics.forward import simulate
from edge.physics.solids import Solid

GLASS = Solid(1.097, 2458.4, 809.0)
ALU = Solid(120.4, 2651.5, 873.0)


def rel_err(a, ref):
    return float(np.max(np.abs(a - ref)) / np.max(np.abs(ref)))


def test_duhamel_constant_flux_is_exact():
    t = np.linspace(0, 2, 101)
    T = surface_temperature(t, np.full(t.size, 500.0), GLASS)
    ana = 2 * 500.0 * np.sqrt(GLASS.alpha_m2_s * t / math.pi) / GLASS.k_W_mK
    assert rel_err(T, ana) < 1e-12


def test_duhamel_linear_ramp_is_exact():
    # q = b t gives T = (4 / 3) b t^1.5 / (e sqrt(pi)).
    t = np.linspace(0, 2, 57)
    b = 300.0
    T = surface_temperature(t, b * t, GLASS)
    ana = (4.0 / 3.0) * b * t ** 1.5 / (GLASS.effusivity_W_s05_m2K * math.sqrt(math.pi))
    assert rel_err(T, ana) < 1e-12


def test_duhamel_depends_only_on_effusivity():
    t = np.linspace(0, 2, 50)
    q = 1000 * (1 - np.exp(-t))
    a = Solid(1.0, 2000.0, 1000.0)
    b = Solid(2.0, 1000.0, 1000.0)  # same e = sqrt(2e6), alpha x4
    np.testing.assert_allclose(surface_temperature(t, q, a), surface_temperature(t, q, b), rtol=1e-12)
    D = duhamel_matrix(t)
    assert np.allclose(np.triu(D, 1), 0.0)


@pytest.mark.parametrize("solid", [GLASS, ALU])
def test_grid_schemes_agree_with_duhamel_on_probe_flux(solid):
    r = simulate(solid, 7.7e7, 1.95, back="infinite", scheme="exact")
    ref = surface_temperature(r.t_s, r.q_f_W_m2, solid)
    # Consistency: the flux-driven model reproduces the probe model's T_f.
    assert rel_err(ref, r.T_f_K) < 1e-3
    assert rel_err(surface_temperature(r.t_s, r.q_f_W_m2, solid, scheme="default"), ref) < 2e-3
    # The paper's explicit scheme at 80 um, not its 40 um: its gap to Duhamel here is set by the
    # flux's 10 ms sampling, not by the grid (aluminium 3.33e-3 at 40, 60 and 80 um alike; glass
    # 3.24e-3 at 40 um, 3.41e-3 at 80 um), and on aluminium the 40 um grid needs ~1.3e5 stable
    # steps, 4x those of 80 um on twice the cells.
    paper = surface_temperature(r.t_s, r.q_f_W_m2, solid, scheme="paper", dx_m=80e-6)
    assert rel_err(paper, ref) < 1e-2


def test_finite_thickness_flux_model_differs_from_semi_infinite():
    t = np.linspace(0, 4, 81)
    q = np.full(t.size, 1000.0)
    pm = Solid(0.185, 1178.35, 1429.0)
    thin = surface_temperature(t, q, pm, thickness_m=0.3e-3, back="insulated", scheme="default")
    inf = surface_temperature(t, q, pm)
    assert thin[-1] > 1.2 * inf[-1]
    with pytest.raises(ValueError, match="duhamel"):
        surface_temperature(t, q, pm, thickness_m=0.3e-3, back="insulated")


def test_flux_model_validation():
    t = np.linspace(0, 1, 10)
    with pytest.raises(ValueError, match="q_W_m2"):
        surface_temperature(t, np.ones(9), GLASS)
    with pytest.raises(ValueError, match="t_s"):
        surface_temperature(t[::-1], np.ones(10), GLASS)
    with pytest.raises(ValueError, match="q_W_m2"):
        surface_temperature(t, np.full(10, np.nan), GLASS)


# --- Duhamel as an O(n) kernel and an FFT product ------------------------------

def _dense_duhamel_reference(t):
    """The dense O(n^2) matrix as edge/fluxmodel.py built it before the kernel form."""
    n = t.size
    h = np.diff(t)
    ti = t[:, None]
    a = np.clip(ti - t[None, 1:], 0.0, None)
    b = np.clip(ti - t[None, :-1], 0.0, None)
    active = ti > t[None, :-1]
    i0 = 2.0 * (np.sqrt(b) - np.sqrt(a))
    i1 = (2.0 / 3.0) * (b ** 1.5 - a ** 1.5)
    D = np.zeros((n, n))
    D[:, :-1] += np.where(active, (-a * i0 + i1) / h, 0.0)
    D[:, 1:] += np.where(active, (b * i0 - i1) / h, 0.0)
    return D / math.sqrt(math.pi)


@pytest.mark.parametrize("n", [2, 3, 10, 201, 600])
def test_duhamel_kernel_product_matches_the_dense_matrix(n):
    from edge.physics.fluxmodel import duhamel_apply

    rng = np.random.default_rng(n)
    t = np.arange(n) * 0.01
    q = 800 * (1 - np.exp(-t / 0.3)) + rng.normal(0, 20, n)
    D = _dense_duhamel_reference(t)
    ref = D @ q
    assert rel_err(duhamel_apply(q, 0.01), ref) < 1e-12
    # Element by element the dense formula itself loses ~k eps to cancellation far below the diagonal.
    assert np.max(np.abs(duhamel_matrix(t) - D)) <= 1e-10 * np.max(np.abs(D))
    # several series at once, and through surface_temperature
    Q = np.column_stack([q, 2 * q])
    np.testing.assert_allclose(duhamel_apply(Q, 0.01)[:, 1], 2 * duhamel_apply(q, 0.01), rtol=1e-13, atol=1e-13)
    if n > 2:
        assert rel_err(surface_temperature(t, q, GLASS) * GLASS.effusivity_W_s05_m2K, ref) < 1e-12


@pytest.mark.skipif(np.finfo(np.longdouble).eps > 1e-18, reason="needs extended precision")
def test_duhamel_kernel_product_against_extended_precision():
    # At 2000 points the dense formula loses digits to cancellation (~4e-12); the kernel does not.
    from edge.physics.fluxmodel import duhamel_apply

    n, dt = 2000, 0.01
    # The dense formula on a uniform grid depends on i - j only: evaluate it once per lag in extended
    # precision and view it as the matrix (the same numbers as n^2 evaluations, at n the cost; a
    # strided view, since filling a 2000 x 2000 extended-precision array costs more than the test).
    lag = np.arange(n, dtype=np.longdouble) * np.longdouble(dt)   # t_i - t_j for i - j = 0 .. n-1

    def piece(m):  # the dense formula's terms at lag t_i - t_j = m dt, zero where t_i <= t_j
        ok = m >= 1
        b = np.where(ok, lag[np.clip(m, 0, n - 1)], 0)               # t_i - t_j
        a = np.where(ok, lag[np.clip(m - 1, 0, n - 1)], 0)           # t_i - t_{j+1}
        i0 = 2 * (np.sqrt(b) - np.sqrt(a))
        i1 = np.longdouble(2) / 3 * (b * np.sqrt(b) - a * np.sqrt(a))
        return (-a * i0 + i1) / np.longdouble(dt), (b * i0 - i1) / np.longdouble(dt)

    m = np.arange(-n, n + 1)
    left, right = piece(m)          # weight on q_j from the interval [t_j, t_{j+1}] (left) and [t_{j-1}, t_j]
    # Windows of the reversed lag tables: row i of window n - i is left[i - j + n], j = 0 .. n-1.
    L = np.lib.stride_tricks.sliding_window_view(left[::-1], n)[n:0:-1]      # L[i, j] = left[i - j + n]
    R = np.lib.stride_tricks.sliding_window_view(right[::-1], n)[n - 1::-1]  # R[i, j] = right[i - j + 1 + n]
    i, j = np.indices((3, 3)) * (n // 3)  # the views are the matrix the index formula describes
    assert np.array_equal(L[i, j], left[i - j + n]) and np.array_equal(R[i, j], right[i - j + 1 + n])
    q = 1000 * (1 - np.exp(-np.arange(n) * dt)) + np.random.default_rng(1).normal(0, 30, n)
    ql = q.astype(np.longdouble)
    ref = (L[:, :-1] @ ql[:-1] + R[:, 1:] @ ql[1:]).astype(float) / math.sqrt(math.pi)
    assert rel_err(duhamel_apply(q, dt), ref) < 1e-14


def test_duhamel_on_a_non_uniform_grid_matches_the_dense_matrix():
    rng = np.random.default_rng(7)
    t = np.arange(301) * 0.01 + np.concatenate(([0.0], rng.uniform(-0.003, 0.003, 300)))  # a jittered clock
    q = 500 + 100 * np.sin(t)
    D = _dense_duhamel_reference(t)
    assert np.max(np.abs(duhamel_matrix(t) - D)) <= 1e-10 * np.max(np.abs(D))
    T = surface_temperature(t, q, GLASS) * GLASS.effusivity_W_s05_m2K
    assert rel_err(T, D @ q) < 1e-12


def test_duhamel_spectrum_cache_is_small_and_bounded():
    from edge.physics.fluxmodel import _duhamel_spectrum, duhamel_apply

    for n in (50, 60, 70, 80, 90, 100):
        duhamel_apply(np.ones(n), 0.01)
    info = _duhamel_spectrum.cache_info()
    assert info.currsize <= info.maxsize <= 8


# --- the graded-grid flux model, uniform knots as one convolution --------------

def _march_linear_loop_reference(ms, t_knots, u_knots, t_out, rows):
    """ModalSolver.march_linear as it was: one _psi evaluation per knot."""
    from edge.physics.integrators import _phi, _psi

    mrows = ms.rows_to_modal(rows)
    lam, beta = ms.lam, ms.beta
    dslope = np.diff(np.concatenate(([0.0], np.diff(u_knots) / np.diff(t_knots))))
    out = (mrows @ (beta[:, None] * _phi(lam[:, None], t_out[None, :]))) * u_knots[0]
    for t0, d in zip(t_knots[:-1], dslope):
        m = t_out > t0
        out[:, m] += d * (mrows @ (beta[:, None] * _psi(lam[:, None], t_out[m][None, :] - t0)))
    return out


# The two intermediate diffusivities (each ~0.02 s of CPU over both backs and both q0) are left to the full
# suite; the bracketing 1e-8 and 3e-4 keep every back and q0 in the fast tier.
@pytest.mark.parametrize("alpha", [1e-8, pytest.param(1e-7, marks=pytest.mark.slow),
                                   pytest.param(1e-6, marks=pytest.mark.slow), 3e-4])
@pytest.mark.parametrize("back", ["insulated", "fixed"])
@pytest.mark.parametrize("q0", [0.0, 150.0])
def test_uniform_march_linear_matches_the_knot_loop(alpha, back, q0):
    from edge.physics import fvm
    from edge.physics.integrators import ModalSolver

    # 2 s of knots on the 4-s grid: the reference loop's cost goes as the knots squared, and every case keeps
    # the modes it had with 4 s in each branch of ramp_response (series, fast, <= 32 steps, the rest).
    t = np.arange(201) * 0.01
    q = q0 + 1000 * (1 - np.exp(-t)) + np.random.default_rng(0).normal(0, 5, t.size)
    q[0] = q0
    unit = Solid(math.sqrt(alpha), 1 / math.sqrt(alpha), 1.0)
    grid = fvm.object_grid(unit, duration_s=4.0, t_first_s=0.01, thickness_m=0.5e-3, back=back)
    ms = ModalSolver(grid)
    r = np.zeros(grid.n)
    r[0] = 1.0
    ref = _march_linear_loop_reference(ms, t, q, t, r)[0]
    assert rel_err(ms.march_linear(t, q, t, r)[0], ref) < 1e-12


def test_surface_temperature_scan_matches_one_call_per_solid():
    from edge.physics.fluxmodel import surface_temperature_scan

    t = np.arange(301) * 0.01
    q = 900 * (1 - np.exp(-t / 0.2))
    solids = [Solid(math.sqrt(a), 1 / math.sqrt(a), 1.0) for a in (1e-8, 3e-7, 2e-5)]
    for tt in (t, np.concatenate((t[:100], t[100:] + 0.003))):  # uniform, and not
        rows = surface_temperature_scan(tt, q, solids, thickness_m=0.6e-3, back="insulated")
        for s, row in zip(solids, rows):
            ref = surface_temperature(tt, q, s, thickness_m=0.6e-3, back="insulated", scheme="default")
            assert rel_err(row, ref) < 1e-12
