"""Verification of the axisymmetric (r, z) world model (firmware_sim/rz).

Each test compares the finite-volume solver with something it does not share
code with: the exact 1-D Laplace solution of the estimator's stack (used here
only as a reference), Carslaw & Jaeger's disk-on-half-space solution, the
1-D contact of two half-spaces, its own refinements (observed orders) and
the energy balance.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from edge.physics.laplace import probe_step_response
from edge.physics.probe import DEFAULT_STACK, PROBE_MATERIAL
from edge.physics.solids import Solid
from firmware_sim.rz.grid import AIR, Boundary, Mesh, graded_faces, half_space_grid, probe_grid
from firmware_sim.rz.solver import Solver, axis_value, steady_state

pytestmark = pytest.mark.slow

GLASS = Solid(k_W_mK=1.1, rho_kg_m3=2500.0, c_J_kgK=800.0)
PMMA = Solid(k_W_mK=0.19, rho_kg_m3=1190.0, c_J_kgK=1470.0)
ALU = Solid(k_W_mK=160.0, rho_kg_m3=2700.0, c_J_kgK=900.0)
FIXED = Boundary(h_W_m2K=math.inf, T_inf_K=0.0)


def observed_order(f: np.ndarray) -> float:
    """Richardson order from values on three grids refined by 2 each time."""
    return math.log2((f[0] - f[1]) / (f[1] - f[2]))


def test_graded_faces_keep_breaks_and_nest():
    x1 = graded_faces([0.0, 1e-3, 5e-3], [1e-4, 1e-6, 1e-3], growth=1.2, max_m=4e-4)
    x2 = graded_faces([0.0, 1e-3, 5e-3], [1e-4, 1e-6, 1e-3], growth=1.2, max_m=4e-4, refine=2)
    assert x1[0] == 0.0 and x1[-1] == 5e-3 and np.any(np.isclose(x1, 1e-3, rtol=0, atol=1e-15))
    h = np.diff(x1)
    assert h.min() == pytest.approx(1e-6, rel=0.5) and h.max() <= 4e-4 * 1.01
    assert np.max(h[1:] / h[:-1]) < 1.2 * 1.05 and np.min(h[1:] / h[:-1]) > 1 / (1.2 * 1.05)
    np.testing.assert_allclose(x2[::2], x1, rtol=0, atol=1e-15)  # refined grid subdivides the coarse one


# ----------------------------------------------------------------------------------------------
# 1. Large heater on a wide object: the 1-D exact (Laplace) solution of the same stack


@pytest.mark.parametrize("solid, R_c", [(GLASS, 0.0), (PMMA, 0.0), (ALU, 0.0), (GLASS, 1e-4)],
                         ids=["glass", "pmma", "alu", "glass-Rc"])
def test_large_heater_matches_1d_laplace(solid, R_c):
    # Heater 0.5 m, object 1 m, insulated sides and top (no substrate: the 1-D model's top),
    # 40 mm object on a fixed-temperature back; the axis is ~0.5 m from any edge, far beyond the
    # 2-s diffusion length (11 mm in aluminium), so the field there is 1-D.
    # Being 1-D, the axis does not see the radial mesh: the heater and object edges are meshed at
    # 5 mm instead of the default 60 um (67 radial cells instead of 158), and the step is 40 ms
    # (TR-BDF2, second order). The errors are the z-discretisation's, the same to 3 digits as
    # with the edge refinement and 10 ms: from 0.08 s, 1.06-1.32e-3 in T (as at 20 ms from 0.1 s) and
    # 0.9-1.1e-3 in q (5-8e-4 at 20 ms from 0.1 s), against 5e-3.
    mesh = Mesh(max_dr_m=0.025, edge_dr_m=5e-3, feature_dr_m=5e-3)
    g = probe_grid(solid, substrate=None, heater_radius_m=0.5, object_radius_m=1.0, object_thickness_m=0.04,
                   contact_resistance_m2K_W=R_c, bottom=FIXED, mesh=mesh)
    dt = 0.04
    rec = Solver(g, dt).step_response(50, per="q_v")
    t = rec.t_s[2:]   # from 0.08 s
    T_ref, q_ref = probe_step_response(solid, t, stack=DEFAULT_STACK, thickness_m=0.04, back="fixed",
                                       contact_resistance_m2K_W=R_c)
    err_T = np.max(np.abs(rec.T_tc_K[2:] - T_ref)) / T_ref[-1]
    err_q = np.max(np.abs(rec.q_face_W_m2[2:] - q_ref)) / q_ref[-1]
    assert err_T < 5e-3, err_T
    assert err_q < 5e-3, err_q
    assert abs(rec.T_tc_K[-1] / T_ref[-1] - 1) < 5e-3
    # The flux sensor sits between heater and object: it reads between the heater's q_v d and q_face.
    assert q_ref[-1] < rec.q_sensor_W_m2[-1] < 1.0 * DEFAULT_STACK.heater_thickness_m  # q_v d, all of it


# ----------------------------------------------------------------------------------------------
# 2. Uniform flux over a disk on a half-space (Carslaw & Jaeger 10.5)


def _ierfc(x: float) -> float:
    return math.exp(-x * x) / math.sqrt(math.pi) - x * math.erfc(x)


def _surface_axis_T(g, T, q_W_m2: float, k: float) -> float:
    """Top-face temperature on the axis: half-cell extrapolation with the imposed flux, then r^2 fit."""
    return float(axis_value(g, T[0, :2] + q_W_m2 * g.dz_m[0] / (2.0 * k)))


def test_disk_on_half_space_transient_and_steady():
    a, q, k, alpha = 5e-3, 1000.0, GLASS.k_W_mK, GLASS.alpha_m2_s
    mesh = Mesh(axis_dr_m=0.5e-3, edge_dr_m=50e-6, max_dr_m=0.02, max_dz_m=0.02)
    g = half_space_grid(GLASS, radius_m=0.1, depth_m=0.1, disk_radius_m=a, fine_m=20e-6, mesh=mesh)
    # 0.5 s steps (4 to the first check): the error is the mesh's, 2.0-3.1e-3 at every check (1.8-3.1e-3
    # with 0.1 or 0.25 s steps: TR-BDF2's time error is at most 6e-4, at 2 s), against the 1 % tolerance.
    dt = 0.5
    solver = Solver(g, dt)
    src = g.top_flux_source_W(a, q)
    T = np.zeros(g.shape)
    t_prev = 0.0
    for t in (2.0, 10.0, 40.0, 120.0):  # a / (2 sqrt(alpha t)) from 2.4 to 0.31
        rec = solver.run(T, int(round((t - t_prev) / dt)), src, 1.0, keep_field=True)
        T, t_prev = rec.T_final_K, t
        s = math.sqrt(alpha * t)
        exact = 2.0 * q * s / k * (_ierfc(0.0) - _ierfc(a / (2.0 * s)))
        got = _surface_axis_T(g, T, q, k)
        assert abs(got / exact - 1) < 0.01, (t, got, exact)
    # Steady value q a / k: fixed temperature far away (2 m = 400 a, truncation ~ a / 2R = 0.1 %).
    mesh = Mesh(axis_dr_m=0.5e-3, edge_dr_m=50e-6, max_dr_m=0.2, max_dz_m=0.2)
    g = half_space_grid(GLASS, radius_m=2.0, depth_m=2.0, disk_radius_m=a, fine_m=20e-6, side=FIXED,
                        bottom=FIXED, mesh=mesh)
    T = steady_state(g, g.top_flux_source_W(a, q))
    assert abs(_surface_axis_T(g, T, q, k) / (q * a / k) - 1) < 0.01


# ----------------------------------------------------------------------------------------------
# 3. Observed orders


def test_observed_order_in_space():
    # A small heater (2 mm) so the radial direction matters at the axis within 1 s, a 0.5-mm
    # sensor disk, foam above, contact resistance; the same dt on every grid (its error cancels
    # in the differences). Grids: one smooth stretching subdivided 1x, 2x, 4x. The step is 50 ms
    # (20 steps to 1 s; the 4x grid is the cost): the observed orders are those of 20 ms steps
    # to 1e-3 (1.993, 1.874, 1.994), so the time error does cancel.
    vals = []
    for refine in (1, 2, 4):
        g = probe_grid(PMMA, heater_radius_m=2e-3, probe_radius_m=4e-3, sensor_radius_m=0.5e-3,
                       object_radius_m=10e-3, object_thickness_m=5e-3, substrate_thickness_m=5e-3,
                       contact_resistance_m2K_W=2e-4,
                       mesh=Mesh(growth=1.3, refine=refine, axis_dr_m=0.3e-3, max_dr_m=2e-3, max_dz_m=2e-3))
        rec = Solver(g, 0.05).step_response(20)
        vals.append((rec.T_tc_K[-1], rec.q_sensor_W_m2[-1], rec.q_face_W_m2[-1]))
    vals = np.array(vals)
    p = [observed_order(vals[:, i]) for i in range(3)]
    assert 1.8 < p[0] < 2.2, p    # thermocouple
    assert 1.7 < p[1] < 2.3, p    # flux sensor (z-trapezoid of face fluxes)
    assert 1.8 < p[2] < 2.2, p    # flux into the object
    # ... and the finest grid is converged well below the 1-D-limit tolerance.
    assert np.all(np.abs(vals[1] - vals[2]) / np.abs(vals[2]) < 2e-3)


@pytest.mark.parametrize("scheme, lo, hi", [("be", 0.9, 1.1), ("cn", 1.9, 2.1), ("trbdf2", 1.9, 2.1)])
def test_observed_order_in_time(scheme, lo, hi):
    # Contact transient (25 on 22) plus 5 W from t = 0: both the jump at the interface and the
    # heater step are started from rest, the hard case for the order of CN.  Read at 1 s (25-100 steps): the
    # orders there are be 0.95-1.02, cn 1.93-2.01, trbdf2 2.004-2.007 (at 2 s: 1.00-1.02, 2.00-2.03, 2.005), in
    # their bands either way, for half the steps; the jump's start-up is if anything a larger share of 1 s.
    g = probe_grid(GLASS, contact_resistance_m2K_W=1e-4, mesh=Mesh(growth=1.3))
    vals = []
    for dt in (0.04, 0.02, 0.01):
        s = Solver(g, dt, scheme)
        rec = s.run(s.initial_field(25.0, 22.0), int(round(1.0 / dt)), s.heater_source_W(), 5.0)
        vals.append((rec.T_tc_K[-1], rec.q_sensor_W_m2[-1], rec.q_face_W_m2[-1]))
    vals = np.array(vals)
    for i in range(3):
        assert lo < observed_order(vals[:, i]) < hi, (i, vals[:, i])


# ----------------------------------------------------------------------------------------------
# 4. Energy conservation


@pytest.mark.parametrize("scheme", ["trbdf2", "cn", "be"])
def test_energy_insulated_exact(scheme):
    # 40-ms steps: each scheme's balance is exact at any step; 50 of them heat 2 s as before.
    g = probe_grid(PMMA, object_thickness_m=0.01, mesh=Mesh(growth=1.3))
    s = Solver(g, 0.04, scheme)
    rec = s.run(s.initial_field(25.0, 22.0), 50, s.heater_source_W(), 3.0)
    assert rec.E_in_J[-1] == pytest.approx(3.0 * 2.0, rel=1e-12)  # the heater disk's volume is exact
    assert np.all(rec.E_lost_J == 0.0)
    assert np.max(np.abs(rec.E_in_J - rec.E_stored_J)) / rec.E_in_J[-1] < 1e-9


def test_energy_with_surface_losses():
    # Convection on the foam top and every side, a thin object on a fixed-temperature back:
    # the losses are a good part of the balance, and the balance still closes.
    amb = Boundary(h_W_m2K=10.0, T_inf_K=20.0)
    g = probe_grid(GLASS, object_thickness_m=2e-3, object_radius_m=0.06, contact_resistance_m2K_W=5e-4,
                   top=amb, side=amb, bottom=Boundary(math.inf, 22.0), mesh=Mesh(growth=1.3))
    s = Solver(g, 0.04)   # the balance closes at any step: 50 steps of 40 ms, the same 2 s and power ramp
    rec = s.run(s.initial_field(25.0, 22.0), 50, s.heater_source_W(), np.linspace(0.0, 8.0, 50))
    E_in = rec.E_in_J[-1]
    assert abs(rec.E_lost_J[-1]) > 0.1 * E_in
    assert np.max(np.abs(rec.E_in_J - rec.E_stored_J - rec.E_lost_J)) / E_in < 1e-6


def test_probe_in_air_both_ways():
    # Held in still air (air as the object) or with a convective bottom face: the balance closes and
    # the thermocouple runs hotter than on glass under the same heating.  40-ms steps (50 to 2 s): the
    # balance closes at any step, and the rises they compare are seconds-long.
    s_glass = Solver(probe_grid(GLASS, mesh=Mesh(growth=1.3)), 0.04)
    T_glass = s_glass.step_response(50).T_tc_K[-1]
    for g in (probe_grid(AIR, mesh=Mesh(growth=1.3)),
              probe_grid(None, bottom=Boundary(10.0, 0.0), mesh=Mesh(growth=1.3))):
        s = Solver(g, 0.04)
        rec = s.run(np.zeros(g.shape), 50, s.heater_source_W(), 2.0)
        assert np.max(np.abs(rec.E_in_J - rec.E_stored_J - rec.E_lost_J)) / rec.E_in_J[-1] < 1e-6
        assert rec.T_tc_K[-1] > 2.0 * 2.5 * T_glass  # ~3.4x: air takes little of the heat
        assert 0 < rec.q_face_W_m2[-1] < rec.q_sensor_W_m2[-1]


# ----------------------------------------------------------------------------------------------
# 5. Contact transient


@pytest.mark.parametrize("solid", [GLASS, PMMA, ALU], ids=["glass", "pmma", "alu"])
def test_contact_transient(solid):
    T_p, T_o = 25.0, 22.0
    dt = 0.002
    s = Solver(probe_grid(solid), dt)
    # 50 steps: the checks below run over 20-100 ms (41 values), where both sides are as semi-infinite as
    # over the 20-200 ms of 100 steps; the first steps' damping, the contact value and the 1-D flux are the same.
    rec = s.free_response(50, T_p, T_o)
    e_p, e_o = PROBE_MATERIAL.effusivity_W_s05_m2K, solid.effusivity_W_s05_m2K
    T_c = (e_p * T_p + e_o * T_o) / (e_p + e_o)
    q = rec.q_face_W_m2[1:]
    assert np.all(q > 0)
    assert np.all(np.diff(q[9:]) < 0)  # decaying once the first steps have damped the jump
    assert np.all((rec.T_tc_K[1:] > T_o) & (rec.T_tc_K[1:] < T_p))
    late = rec.t_s >= 10 * dt  # 20 ms .. 0.1 s: both sides look semi-infinite
    assert np.max(np.abs(rec.T_tc_K[late] - T_c)) < 0.01 * (T_p - T_o)
    q_1d = (T_p - T_o) * e_p * e_o / (e_p + e_o) / np.sqrt(np.pi * rec.t_s[late])
    assert np.max(np.abs(rec.q_face_W_m2[late] / q_1d - 1)) < 0.01
    # The thermopile spans the layer: it reads k dT / L across it, below the face flux early on.
    assert np.all((rec.q_sensor_W_m2[late] > 0) & (rec.q_sensor_W_m2[late] < rec.q_face_W_m2[late]))


# ----------------------------------------------------------------------------------------------
# Linearity: superposed unit steps equal a direct run


def test_superposition_equals_direct_run():
    g = probe_grid(PMMA, contact_resistance_m2K_W=1e-4, top=Boundary(5.0, 21.0), side=Boundary(5.0, 21.0),
                   mesh=Mesh(growth=1.3))
    s = Solver(g, 0.02)
    n = 50   # linearity is exact at any length: 50 steps hold 5 switchings of the PWM
    power = np.where((np.arange(n) // 10) % 2 == 0, 4.0, 1.0)  # a slow PWM
    direct = s.run(s.initial_field(25.0, 22.0), n, s.heater_source_W(), power)
    sup = Solver.superpose(s.free_response(n, 25.0, 22.0), s.step_response(n), power)
    for name in ("T_tc_K", "q_sensor_W_m2", "q_face_W_m2"):
        d = getattr(direct, name)
        assert np.max(np.abs(sup[name] - d)) <= 1e-9 * np.max(np.abs(d)), name
