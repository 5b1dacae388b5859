"""The probe forward model: analytical references, convergence, extremes, validation."""

import math

import numpy as np
import pytest

from edge.physics import fvm, laplace
from edge.physics.forward import scale_levels, simulate, step_response
from edge.physics.integrators import ModalSolver, explicit_march
from edge.physics.schedule import PowerSchedule
from edge.physics.probe import STACK_040, STACK_042
from edge.physics.solids import Solid

GLASS = Solid(1.097, 2458.4, 809.0)
PMMA = Solid(0.185, 1178.35, 1429.0)
ALU = Solid(120.4, 2651.5, 873.0)
TABLE1 = [Solid(0.1, 500.2, 2400), Solid(1.5, 2659.6, 800), Solid(12, 7860, 477.1)]


def rel_err(a, ref):
    return float(np.max(np.abs(a - ref)) / np.max(np.abs(ref)))


# --- analytical references ---------------------------------------------------

def test_talbot_inverts_semi_infinite_constant_flux():
    # L{2 q sqrt(alpha t / pi) / k} = q / (e s^1.5) for a surface flux q.
    t = np.linspace(0.01, 3.0, 40)
    e, q = 1700.0, 800.0
    f = laplace.talbot_invert(lambda s: q / (e * s ** 1.5), t)
    ana = 2 * q * np.sqrt(t / math.pi) / e
    assert rel_err(f, ana) < 1e-10


def test_fv_grid_semi_infinite_constant_flux_matches_closed_form():
    # The graded object grid under a surface flux: T = 2 q sqrt(alpha t / pi) / k.
    t = np.linspace(0.0, 2.0, 201)
    for s in (PMMA, ALU):
        g = fvm.object_grid(s, duration_s=2.0, t_first_s=0.01, thickness_m=None, back="infinite")
        r = np.zeros(g.n)
        r[0] = 1.0
        T = ModalSolver(g).march(PowerSchedule.constant(1000.0), t, r).outputs[0]
        ana = 2 * 1000.0 * np.sqrt(s.alpha_m2_s * t / math.pi) / s.k_W_mK
        assert rel_err(T, ana) < 2e-3


@pytest.mark.parametrize("solid", [GLASS, PMMA, ALU] + TABLE1)
def test_default_scheme_within_0p1_percent_of_exact(solid):
    ref = simulate(solid, 7.7e7, 1.95, scheme="exact")
    r = simulate(solid, 7.7e7, 1.95, scheme="default")
    assert rel_err(r.T_f_K, ref.T_f_K) < 1e-3
    assert rel_err(r.q_f_W_m2, ref.q_f_W_m2) < 1e-3


def test_paper_interface_costs_percent_level_bias():
    # The paper's interface node drops the sensing half cell: a few % on PMMA at 40 um.
    ref = simulate(PMMA, 7.7e7, 1.95, scheme="exact")
    paper = simulate(PMMA, 7.7e7, 1.95, scheme="paper")
    consistent = simulate(PMMA, 7.7e7, 1.95, scheme="explicit")
    assert rel_err(paper.T_f_K, ref.T_f_K) > 0.01
    assert rel_err(consistent.T_f_K, ref.T_f_K) < 0.3 * rel_err(paper.T_f_K, ref.T_f_K)


def _orders(errs):
    errs = np.asarray(errs)
    return np.log2(errs[:-1] / errs[1:])


@pytest.mark.slow  # grid refinements of three schemes
def test_observed_convergence_orders():
    ref = simulate(GLASS, 1.0, 1.95, scheme="exact")
    paper, explicit, default = [], [], []
    for lev in range(4):
        dx = 0.42e-3 / (5 * 2 ** lev)  # exact halvings with the interface on a node
        # The paper scheme is first order from the coarsest grid on (orders 1.02, 0.94): three levels show it;
        # its fourth (a forward-Euler march of 23 400 steps, half this test's CPU) added a third, 1.02.
        if lev < 3:
            paper.append(rel_err(simulate(GLASS, 1.0, 1.95, scheme="paper", dx_m=dx).T_f_K, ref.T_f_K))
        explicit.append(rel_err(simulate(GLASS, 1.0, 1.95, scheme="explicit", dx_m=dx).T_f_K, ref.T_f_K))
    for lev in range(4):
        r = simulate(GLASS, 1.0, 1.95, scheme="default", n_probe=6 * 2 ** lev, growth=1.2 ** (1 / 2 ** lev))
        default.append(rel_err(r.T_f_K, ref.T_f_K))
    # Paper scheme: first order (the interface capacity); consistent schemes: second.
    assert np.all(np.abs(_orders(paper) - 1.0) < 0.25), paper
    # Space and time errors have opposite signs on coarse grids; the asymptotic order shows last.
    assert _orders(explicit)[-1] > 1.7, explicit
    assert np.mean(_orders(default)) > 1.7, default


def test_stacking_choice_changes_T_f_by_percent():
    a = simulate(GLASS, 7.7e7, 1.95, stack=STACK_042)
    b = simulate(GLASS, 7.7e7, 1.95, stack=STACK_040)
    diff = abs(a.T_f_K[-1] - b.T_f_K[-1]) / b.T_f_K[-1]
    assert 0.005 < diff < 0.2


def test_backs_order_as_physics_says():
    # A thin slab: insulated back stores heat (hotter), fixed back sinks it (cooler).
    kw = dict(thickness_m=0.5e-3)
    ins = simulate(PMMA, 7.7e7, 4.0, back="insulated", **kw)
    fix = simulate(PMMA, 7.7e7, 4.0, back="fixed", **kw)
    inf = simulate(PMMA, 7.7e7, 4.0, back="infinite")
    assert ins.T_f_K[-1] > inf.T_f_K[-1] > fix.T_f_K[-1]
    for back in ("insulated", "fixed"):
        ex = simulate(PMMA, 7.7e7, 4.0, back=back, scheme="exact", **kw)
        de = simulate(PMMA, 7.7e7, 4.0, back=back, **kw)
        assert rel_err(de.T_f_K, ex.T_f_K) < 2e-3


def test_linearity_and_superposition():
    unit = step_response(GLASS, 1.95)
    T, q = scale_levels(unit, [4e7, 1.4e8])
    direct = simulate(GLASS, 1.4e8, 1.95)
    np.testing.assert_allclose(T[1], direct.T_f_K, rtol=1e-12, atol=1e-15)
    # A PWM-averaged series equals the sum of its steps, for every scheme.
    times = np.array([0.0, 0.5, 1.0, 1.5])
    levels = np.array([1e8, 5e7, 1.2e8, 0.0])
    for scheme in ("default", "exact", "paper"):
        r = simulate(GLASS, levels, 1.95, q_v_times_s=times, scheme=scheme)
        acc = np.zeros_like(r.T_f_K)
        prev = 0.0
        for t0, lv in zip(times, levels):
            part = simulate(GLASS, 1.0, 1.95, scheme=scheme).T_f_K
            shifted = np.interp(r.t_s - t0, r.t_s, part, left=0.0)
            acc += (lv - prev) * np.where(r.t_s >= t0, shifted, 0.0)
            prev = lv
        assert rel_err(r.T_f_K, acc) < 1e-6 if scheme != "paper" else 2e-3


@pytest.mark.slow  # every scheme marched over a stepped schedule
def test_schemes_agree_on_stepped_power():
    # On a stainless steel (errors 3.4e-4 and 4.7e-3): aluminium's diffusivity held the paper's explicit march to
    # 115 000 steps (0.45 CPU-s; errors 3.5e-4 and 2.3e-3), steel's to 9 200; glass's interface error
    # (2.0e-2) is the paper scheme's first-order bias that test_paper_interface_costs_percent_level_bias shows.
    steel = Solid(16.0, 7900.0, 500.0)
    times = np.array([0.0, 0.7, 1.3])
    levels = np.array([6e7, 1.3e8, 2e7])
    ex = simulate(steel, levels, 1.95, q_v_times_s=times, scheme="exact")
    de = simulate(steel, levels, 1.95, q_v_times_s=times)
    pa = simulate(steel, levels, 1.95, q_v_times_s=times, scheme="paper")
    assert rel_err(de.T_f_K, ex.T_f_K) < 1e-3
    assert rel_err(pa.T_f_K, ex.T_f_K) < 1e-2


# --- extremes ------------------------------------------------------------------

EXTREME_SOLIDS = [
    Solid(0.02, 1e4, 1.0), Solid(0.02, 5e6, 1.0), Solid(2000.0, 1e4, 1.0), Solid(2000.0, 5e6, 1.0),
    Solid(1.0, 2e6, 1.0),
]


@pytest.mark.parametrize("solid", EXTREME_SOLIDS, ids=lambda s: f"k{s.k_W_mK:g}-rc{s.rho_c_J_m3K:g}")
@pytest.mark.parametrize("duration", [0.01, 2.0, 60.0])
@pytest.mark.parametrize("back", ["fixed", "infinite"])
def test_extremes_finite_monotone_energy_closed(solid, duration, back):
    q_v = 1e9
    r = simulate(solid, q_v, duration, back=back)
    assert np.all(np.isfinite(r.T_f_K)) and np.all(np.isfinite(r.q_f_W_m2))
    # Round-off is judged against the physical scales: the heater's own
    # adiabatic rise and the heat it releases per second.
    p = STACK_042
    dT_scale = q_v * p.heater_thickness_m * duration / (p.material.rho_c_J_m3K * p.total_thickness_m)
    q_scale = q_v * p.heater_thickness_m
    assert np.all(np.diff(r.T_f_K) >= -1e-12 * dT_scale), "step heating must warm monotonically"
    assert np.all(r.q_f_W_m2 >= -1e-12 * q_scale)
    assert np.all(np.diff(r.q_f_W_m2) >= -1e-12 * q_scale)
    assert abs(r.energy_residual) < 1e-3
    ex = simulate(solid, q_v, duration, back=back, scheme="exact")
    assert np.max(np.abs(r.T_f_K - ex.T_f_K)) < 5e-3 * np.max(ex.T_f_K) + 1e-9 * dT_scale


def test_zero_power_gives_zero_everywhere():
    for scheme in ("default", "paper", "exact"):
        r = simulate(GLASS, 0.0, 0.5, scheme=scheme)
        assert np.all(r.T_f_K == 0) and np.all(r.q_f_W_m2 == 0)
        assert r.energy_residual == 0.0


def test_explicit_energy_balance_closes_with_fixed_back_leak():
    # Copper-like diffusivity over 20 s: heat reaches the held back of a 5 mm block.
    s = Solid(50.0, 4e6, 1.0)
    r = simulate(s, 1e8, 20.0, thickness_m=5e-3, back="fixed", scheme="explicit", dx_m=200e-6)
    assert r.energy_J_m2["conducted_out"] > 0.01 * r.energy_J_m2["released"]
    assert abs(r.energy_residual) < 1e-9
    d = simulate(s, 1e8, 20.0, thickness_m=5e-3, back="fixed")
    assert d.energy_J_m2["conducted_out"] > 0.01 * d.energy_J_m2["released"]
    assert abs(d.energy_residual) < 1e-3


def test_explicit_refuses_runs_beyond_step_budget():
    with pytest.raises(ValueError, match="max_steps"):
        simulate(Solid(2000.0, 1e4, 1.0), 1e8, 60.0, scheme="paper")


# --- validation ------------------------------------------------------------------

@pytest.mark.parametrize(
    "kwargs,name",
    [
        (dict(k_W_mK=-1.0, rho_kg_m3=1000.0, c_J_kgK=1000.0), "k_W_mK"),
        (dict(k_W_mK=1.0, rho_kg_m3=float("nan"), c_J_kgK=1000.0), "rho_kg_m3"),
        (dict(k_W_mK=1.0, rho_kg_m3=1000.0, c_J_kgK=0.0), "c_J_kgK"),
    ],
)
def test_invalid_properties_name_the_argument(kwargs, name):
    with pytest.raises(ValueError, match=name):
        Solid(**kwargs)


@pytest.mark.parametrize(
    "args,kwargs,name",
    [
        ((1e8, 0.0), {}, "duration_s"),
        ((1e8, -1.0), {}, "duration_s"),
        ((float("nan"), 1.0), {}, "q_v_W_m3"),
        ((-5.0, 1.0), {}, "q_v_W_m3"),
        ((np.array([1e8, 2e8]), 1.0), dict(q_v_times_s=[0.0]), "q_v"),
        ((np.array([1e8, 2e8]), 1.0), {}, "q_v_times_s"),
        ((np.array([1e8, 2e8]), 1.0), dict(q_v_times_s=[0.0, 0.0]), "q_v_times_s"),
        ((1e8, 1.0), dict(back="floating"), "back"),
        ((1e8, 1.0), dict(scheme="magic"), "scheme"),
        ((1e8, 1.0), dict(thickness_m=-0.01), "thickness_m"),
        ((1e8, 1.0), dict(dt_s=0.0), "dt_s"),
        ((1e8, 1.0), dict(t_s=[0.0, 2.0]), "t_s"),
    ],
)
def test_invalid_arguments_name_the_argument(args, kwargs, name):
    with pytest.raises(ValueError, match=name):
        simulate(GLASS, *args, **kwargs)


@pytest.mark.parametrize("n", [40, 512, 513, 1500])   # both of causal_convolution's branches
def test_one_kernel_over_columns_is_the_columns_one_by_one_bit_for_bit(n):
    from edge.physics.integrators import causal_convolution, causal_convolution_columns

    rng = np.random.default_rng(n)
    g, D = rng.normal(size=n), rng.normal(size=(n, 3))
    one_by_one = np.column_stack([causal_convolution(g, D[:, j]) for j in range(3)])
    assert np.array_equal(causal_convolution_columns(g, D), one_by_one)
    # and it is the convolution: out[i] = sum_{j <= i} g[i - j] d[j]
    i = n - 1
    assert causal_convolution_columns(g, D)[i, 1] == pytest.approx(float(g[i::-1] @ D[:i + 1, 1]), rel=1e-9)
