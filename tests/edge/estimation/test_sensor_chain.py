"""Verification of edge.estimation.sensor_chain (ISSUE #10 §3).

(1) Self-consistency: exact records of the same 1-D chain recover (e, R_c, T_obj0).  Necessary,
not sufficient.  (2) The independent FaithfulWorld (axisymmetric FV, 1-D-limit geometry) with
R_c = 1e-4 m^2K/W, the object 1 K colder and contact 1 s before heater-on, precision-board noise:
e within 3 % and within its stated 2u, T_obj0 within 50 mK, R_c within 30 %.  (The
comparison with the default Estimator on these records is not here yet: it needs a model bundle.)
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from edge.estimation.sensor_chain import SensorChainCalibration, fit_sensor_chain, simulate_chain

DT_s = 0.05


def test_self_consistent_chain_recovers_its_parameters():
    rng = np.random.default_rng(1)
    t = np.arange(0.0, 15.0, DT_s)
    q = np.where(t > 1.0, 3000.0, 0.0) * (1 - np.exp(-np.clip(t - 1.0, 0, None) / 0.3))
    for e, rc, tau in ((1500.0, 1e-4, 0.0), (560.0, 3e-5, 0.1), (20000.0, 1e-4, 0.0)):
        cal = SensorChainCalibration(tc_tau_s=tau)
        T = simulate_chain(t, q, e_W_s05_m2K=e, R_c_m2K_W=rc, T_obj0_C=24.0, T_probe0_C=25.0, calibration=cal)
        # Unsmoothed and on the record's own samples (inputs linear between them): the fit's model is
        # then the simulator's exactly.
        r = fit_sensor_chain(t, T, q, calibration=cal, smooth_s=0.0, refine_dt_s=None)
        # The default smooths theta_b against noise, at a small cost on a noise-free record.
        assert fit_sensor_chain(t, T, q, calibration=cal, breaks_s=(1.0,)).e_W_s05_m2K == pytest.approx(e, rel=5e-3)
        # Exact without lag; with it the de-lagged reading stands in for theta_b in the storage term.
        tol = 1e-6 if tau == 0 else 2e-2
        assert r.e_W_s05_m2K == pytest.approx(e, rel=tol)
        if tau == 0:
            # With a bead lag R_c and T_obj0 are not yet recovered (open: the de-lagged reading in the
            # storage term trades against R_c over the first samples).
            assert r.R_c_m2K_W == pytest.approx(rc, rel=tol, abs=1e-7)
            assert r.T_obj0_C == pytest.approx(24.0, abs=1e-6)
        # With noise the estimate is still within 2u.
        Tn = T + 0.01 * rng.standard_normal(t.size)
        qn = q + 0.5 * rng.standard_normal(t.size)
        r = fit_sensor_chain(t, Tn, qn, calibration=cal, breaks_s=(1.0,))
        assert abs(r.e_W_s05_m2K - e) < 2.5 * r.u_e_W_s05_m2K + tol * e


def _faithful_record(name: str):
    from firmware_sim.clock import VirtualClock
    from firmware_sim.rz.grid import Mesh
    from firmware_sim.rz.probe_world import FaithfulWorld, Geometry
    from firmware_sim.scene.files import read_scene
    from firmware_sim.world import ScheduleDrive

    one_d = Geometry(substrate=None, h_air_W_m2K=0.0, heater_radius_m=0.1, object_radius_m=0.15,
                     mesh=Mesh(max_dr_m=0.01))
    sc = read_scene(name)
    env = sc.environment
    sc = dataclasses.replace(
        sc, environment=dataclasses.replace(env, initial_temperature_C=env.ambient_temperature_C - 1.0),
        touch=dataclasses.replace(sc.touch, start_s=1.0, length_s=20.0), contact_resistance_m2K_W=1e-4)
    clk = VirtualClock()
    clk.advance(100.0)
    w = FaithfulWorld(sc, clk, ScheduleDrive([2.0, 10.0], [1.0, 0.0]), geometry=one_d, dt_s=0.05)
    t = 1.0 + np.arange(0.0, 12.0, DT_s)    # from contact; heater on at 1 s after contact
    s = w.series(t)
    return t - 1.0, s["y"], s["q_sensor"], sc.object.solid.effusivity_W_s05_m2K, env.ambient_temperature_C


@pytest.mark.slow  # twelve seconds of the faithful world per scene
@pytest.mark.parametrize("name", ["glass_15V", "pmma_15V"])
def test_faithful_world_contact_resistance_cold_object_and_depth_average(name):
    t, T, q, e_true, T_amb = _faithful_record(name)
    rng = np.random.default_rng(7)
    Tn = T + 0.01 * rng.standard_normal(t.size)
    qn = q + 0.5 * rng.standard_normal(t.size)
    r = fit_sensor_chain(t, Tn, qn)
    err = r.e_W_s05_m2K / e_true - 1.0
    assert abs(err) < 0.03
    assert r.T_obj0_C == pytest.approx(T_amb - 1.0, abs=0.05) and r.R_c_m2K_W == pytest.approx(1e-4, rel=0.3)
    z = abs(r.e_W_s05_m2K - e_true) / r.u_e_W_s05_m2K
    if name == "pmma_15V" and z >= 2.0:
        # Known gap: error -0.2 % against u(e) 0.1 % (z ~ 2.0, normalised residual ~2): the stated
        # u has no model-error / noisy-regressor term yet, so coverage is not yet shown.
        pytest.xfail(f"stated u(e) too small on PMMA: z = {z:.2f}")
    assert z < 2.0


@pytest.mark.parametrize("n, e, rc, tau", [(50, 558.0, 0.0, 0.0), (300, 1500.0, 2e-5, 0.06), (517, 200.0, 1e-4, 0.03)])
def test_blocked_causal_solve_equals_the_dense_system(n, e, rc, tau):
    # The oracle: the chain's implicit model as one dense n x n system, (I + B Z) phi = A q, built
    # column by column from the module's own operators.  The blocked solve must be the same numbers
    # across block edges (n > SIMULATE_BLOCK) and within one block.
    from edge.estimation.sensor_chain import SIMULATE_BLOCK, _apply, _lag, _slab_kernels
    from edge.physics.fluxmodel import duhamel_apply

    assert n < SIMULATE_BLOCK or n % SIMULATE_BLOCK != 0
    rng = np.random.default_rng(n)
    dt = 0.02
    t = np.arange(n) * dt
    q = np.where(t > 0.5, 2000.0, 0.0) + 5.0 * rng.standard_normal(n)
    q[0] = 0.0
    cal = SensorChainCalibration(tc_tau_s=tau)
    got = simulate_chain(t, q, e_W_s05_m2K=e, R_c_m2K_W=rc, T_obj0_C=24.3, T_probe0_C=25.0, calibration=cal)
    KA, KB = _slab_kernels(n, dt, cal.sensing_thickness_m, cal.k_W_mK, cal.alpha_m2_s)
    eye = np.eye(n)
    MB = np.column_stack([_apply(KB, eye[:, j]) for j in range(n)])
    Zm = rc * eye + duhamel_apply(eye, dt) / e
    phi = np.linalg.solve(eye + MB @ Zm, _apply(KA, q * cal.flux_scale))
    want = 25.0 + _lag((-0.7 + Zm @ phi)[:, None], dt, tau)[:, 0]
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9 * max(1.0, float(np.max(np.abs(want - 25.0)))))


@pytest.mark.parametrize("disk", [None, (0.03, 5e-5), (0.03, 1e-7)])
def test_disk_fitter_gives_fit_sensor_chains_numbers(disk):
    """DiskFitter shares the disk-independent columns across calls: the same fit as fit_sensor_chain."""
    from edge.estimation.sensor_chain import DiskFitter

    rng = np.random.default_rng(4)
    t = np.arange(0.0, 8.0, DT_s)
    q = np.where(t > 1.0, 2500.0, 300.0 / np.sqrt(1.0 + t))
    cal = SensorChainCalibration(tc_tau_s=0.06)
    T = simulate_chain(t, q, e_W_s05_m2K=9000.0, R_c_m2K_W=2e-5, T_obj0_C=24.0, T_probe0_C=25.0, calibration=cal)
    T = T + 0.004 * rng.standard_normal(t.size)
    kw = dict(calibration=cal, fit_start_s=0.3, noise_T_K=0.004, breaks_s=(1.0,))
    f = DiskFitter(t, T, q, **kw)
    f(None)                                    # a call before must not change the next one
    a, b = f(disk), fit_sensor_chain(t, T, q, disk=disk, **kw)
    for name in ("e_W_s05_m2K", "u_e_W_s05_m2K", "R_c_m2K_W", "u_R_c_m2K_W", "T_obj0_C", "rms_residual_K",
                 "residual_inflation"):
        assert getattr(a, name) == pytest.approx(getattr(b, name), rel=1e-9, abs=1e-12), name
    assert a.n_fitted == b.n_fitted == int(np.sum(t >= 0.3))


@pytest.mark.parametrize("dt,tau,n", [(0.05, 0.06, 300), (0.01, 0.1, 2000), (0.08, 0.01, 50), (0.001, 0.2, 700)])
def test_lag_as_a_convolution_is_the_recursion(dt, tau, n):
    from edge.estimation.sensor_chain import _lag

    rng = np.random.default_rng(7)
    x = np.column_stack((np.ones(n), np.cumsum(rng.standard_normal(n)), 1e3 * rng.standard_normal(n)))
    # The bead's first-order lag, exact for x linear between samples (the definition).
    a = np.exp(-dt / tau)
    b = 1.0 - tau * (1.0 - a) / dt
    ref = np.zeros_like(x)
    for i in range(1, n):
        ref[i] = a * ref[i - 1] + (1.0 - a) * x[i - 1] + b * (x[i] - x[i - 1])
    got = _lag(x, dt, tau)
    assert np.allclose(got, ref, rtol=1e-10, atol=1e-10 * np.max(np.abs(x), axis=0))
    assert _lag(x, dt, 0.0) is x


def test_disk_fitter_point_is_the_full_fits_e_and_residual():
    from edge.estimation.sensor_chain import DiskFitter

    rng = np.random.default_rng(5)
    t = np.arange(0.0, 8.0, DT_s)
    q = np.where(t > 1.0, 2500.0, 300.0 / np.sqrt(1.0 + t))
    cal = SensorChainCalibration(tc_tau_s=0.06)
    T = simulate_chain(t, q, e_W_s05_m2K=9000.0, R_c_m2K_W=2e-5, T_obj0_C=24.0, T_probe0_C=25.0, calibration=cal)
    f = DiskFitter(t, T + 0.004 * rng.standard_normal(t.size), q, calibration=cal, noise_T_K=0.004, breaks_s=(1.0,))
    for disk in (None, (0.03, 5e-5), (0.03, 2e-4)):
        full, pt = f(disk), f.point(disk)
        assert pt.e_W_s05_m2K == pytest.approx(full.e_W_s05_m2K, rel=1e-9)
        assert pt.rms_residual_K == pytest.approx(full.rms_residual_K, rel=1e-9)
        assert pt.residual_inflation == pytest.approx(full.residual_inflation, rel=1e-9)
        assert pt.n_fitted == full.n_fitted


@pytest.mark.parametrize("frac", [0.0, 0.4, 0.8])
def test_chain_design_models_the_contact_instant_the_fit_does(frac):
    """The calibration fits through chain_design, the estimator through fit_sensor_chain: at any contact
    instant within the first (refined) interval both must be the same linear model, or a calibration
    fitted with one contact instant is applied to touches modelled with another (ISSUE #34)."""
    from edge.estimation.sensor_chain import chain_design

    rng = np.random.default_rng(11)
    t = np.arange(0.0, 4.0, 0.1)                       # the device's 10 Hz: refined to 20 ms
    q = np.where(t > 1.0, 2500.0, 600.0)
    q[0] = 0.0                                         # the last sample in air
    cal = SensorChainCalibration(tc_tau_s=0.01)
    T = simulate_chain(t, q, e_W_s05_m2K=700.0, R_c_m2K_W=1e-5, T_obj0_C=23.0, T_probe0_C=25.0, calibration=cal,
                       ) + 0.003 * rng.standard_normal(t.size)
    kw = dict(calibration=cal, fit_start_s=0.3, breaks_s=(1.0,))
    X, y = chain_design(t, T, q, contact_frac=frac, **kw)
    p = np.linalg.lstsq(X, y, rcond=None)[0]
    r = fit_sensor_chain(t, T, q, contact_frac=frac, **kw)
    assert 1.0 / p[2] == pytest.approx(r.e_W_s05_m2K, rel=1e-6)
    assert p[1] == pytest.approx(r.R_c_m2K_W, rel=1e-6, abs=1e-12)
    # ... and the contact instant changes the model (it is not ignored).
    X0, _ = chain_design(t, T, q, contact_frac=0.0 if frac else 0.6, **kw)
    assert not np.allclose(X0[-30:], X[-30:])


def test_refine_factor_runs_50_hz_at_5_ms_and_keeps_10_hz_on_its_20_ms_grid():
    """ISSUE #34 item 5: the 50-Hz precision board's contact instant is placed within its 20-ms interval."""
    from edge.estimation.sensor_chain import MAX_REFINE, refine_factor

    assert refine_factor(0.1) == MAX_REFINE == 5          # 10 Hz: 20 ms, as validated before
    assert refine_factor(0.02) == 4                       # 50 Hz: 5 ms
    assert refine_factor(0.005) == 1 and refine_factor(0.02, None) == 1


def test_the_fits_noise_part_is_the_white_noise_bound_and_the_storage_term_adds_to_it():
    """u_ln_e_noise is the fit's u on the stated noise alone: the scatter of ln e when white noise enters
    the record only (the design fixed, as in the Fisher bound of edge.estimation.design).  The
    thermocouple's noise also enters the storage term (errors in variables), so the real fit scatters
    more, and its stated u (residual, lag-1 inflation) is what covers that; knowing the nuisances
    (T_obj0, R_c) can only lower the noise part."""
    from edge.estimation.sensor_chain import chain_design

    rng = np.random.default_rng(5)
    t = np.arange(0.0, 1.5, 0.02)
    q = np.where(t > 0.5, 2500.0, 600.0)
    cal = SensorChainCalibration()
    T = simulate_chain(t, q, e_W_s05_m2K=600.0, R_c_m2K_W=2e-5, T_obj0_C=23.0, T_probe0_C=25.0, calibration=cal)
    sigma, kw = 0.005, dict(calibration=cal, breaks_s=(0.5,))
    X, y = chain_design(t, T, q, T_probe0_C=25.0, **kw)
    fixed = [np.linalg.lstsq(X, y + sigma * rng.standard_normal(y.size), rcond=None)[0][2] for _ in range(200)]
    got = [fit_sensor_chain(t, T + sigma * rng.standard_normal(t.size), q, smooth_s=0.0, noise_T_K=sigma,
                            T_probe0_C=25.0, **kw) for _ in range(100)]
    u_noise = float(np.median([r.u_ln_e_noise for r in got]))
    assert u_noise == pytest.approx(float(np.std(np.log(fixed))), rel=0.2)
    scatter = float(np.std([np.log(r.e_W_s05_m2K) for r in got]))
    assert scatter > 1.3 * u_noise
    assert float(np.median([r.u_e_W_s05_m2K / r.e_W_s05_m2K for r in got])) == pytest.approx(scatter, rel=0.3)
    assert all(r.u_ln_e_noise_nuisance_known <= r.u_ln_e_noise for r in got)


def test_chain_point_is_the_full_fits_e_and_residual_and_repeats_are_the_same_numbers():
    """chain_point (the contact-instant search's fit) answers the full fit's e and rms residual exactly,
    and a second evaluation -- from the kept kernels and design pieces -- the same bits as the first."""
    from edge.estimation.sensor_chain import _KERNELS, chain_point

    rng = np.random.default_rng(7)
    t = np.arange(0.0, 6.0, 0.1)
    q = np.where(t > 1.0, 2500.0, 0.0) * (1 - np.exp(-np.clip(t - 1.0, 0, None) / 0.3))
    cal = SensorChainCalibration(tc_tau_s=0.05)
    T = simulate_chain(t, q, e_W_s05_m2K=900.0, R_c_m2K_W=2e-5, T_obj0_C=25.0, T_probe0_C=25.0, calibration=cal)
    T = T + 0.005 * rng.standard_normal(t.size)
    for frac in (0.0, 0.2, 0.6):
        full = fit_sensor_chain(t, T, q, calibration=cal, breaks_s=(1.0,), contact_frac=frac)
        pt = chain_point(t, T, q, calibration=cal, breaks_s=(1.0,), contact_frac=frac)
        assert pt.e_W_s05_m2K == full.e_W_s05_m2K
        assert pt.rms_residual_K == full.rms_residual_K
        assert pt.n_fitted == full.n_fitted
        _KERNELS.clear()   # computed afresh: a shorter grid's kernels are a prefix of a longer one's
        again = fit_sensor_chain(t, T, q, calibration=cal, breaks_s=(1.0,), contact_frac=frac)
        assert again.e_W_s05_m2K == full.e_W_s05_m2K and again.R_c_m2K_W == full.R_c_m2K_W
