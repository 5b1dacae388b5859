"""The small heater's k and alpha where the fit is informative but not decisive: the fit weighted with the prior."""

from __future__ import annotations

import math

import numpy as np
import pytest

from edge.estimation.probe_estimate import k_alpha_posterior

H = np.array([1.0, -1.0])        # ln rho c = ln k - ln alpha


def test_a_flat_prior_leaves_the_fit():
    V = np.array([[0.04, -0.05], [-0.05, 0.09]])
    x, Vp, share = k_alpha_posterior(math.log(0.2), math.log(1e-7), V, math.log(2e6), 1e6)
    assert x == pytest.approx([math.log(0.2), math.log(1e-7)], abs=1e-9)
    assert Vp == pytest.approx(V, abs=1e-12)
    assert share == pytest.approx(1.0, abs=1e-9)


def test_a_fit_flat_along_rho_c_gives_the_prior_given_its_e():
    # The fit fixes ln e = ln k - ln alpha / 2 to 1 % and says next to nothing about ln rho c.
    G = np.array([1.0, -0.5])                       # ln e
    A = np.vstack([G, H])                           # (ln e, ln rho c) = A (ln k, ln alpha)
    Ai = np.linalg.inv(A)
    V = Ai @ np.diag([0.01 ** 2, 1e8]) @ Ai.T
    ln_e, ln_rc_fit = math.log(600.0), math.log(1.5e6)
    x0 = Ai @ np.array([ln_e, ln_rc_fit])
    ln_rc, u_rc = math.log(2.0e6), 0.25
    x, Vp, share = k_alpha_posterior(x0[0], x0[1], V, ln_rc, u_rc)
    assert share < 1e-8
    assert H @ x == pytest.approx(ln_rc, abs=1e-6)          # the prior's rho c
    assert G @ x == pytest.approx(ln_e, abs=1e-6)           # the touch's e
    # ... with the prior's spread: var ln k = 4 var ln e + var ln rho c, var ln alpha = 4 var ln e + 4 var ln rho c.
    assert Vp[0, 0] == pytest.approx(4 * 0.01 ** 2 + u_rc ** 2, rel=1e-6)
    assert Vp[1, 1] == pytest.approx(4 * 0.01 ** 2 + 4 * u_rc ** 2, rel=1e-6)


def test_precision_weighting_in_between():
    # Equal variances of ln rho c from the fit and the prior: the mean halfway, its variance halved.
    V = np.array([[0.05, 0.0], [0.0, 0.04]])                 # fit's var ln rho c = 0.09
    x, Vp, share = k_alpha_posterior(0.0, 0.0, V, 0.6, 0.3)
    assert share == pytest.approx(0.5)
    assert H @ x == pytest.approx(0.3)
    assert H @ Vp @ H == pytest.approx(0.045)
    assert np.all(np.linalg.eigvalsh(Vp) > 0)


def test_a_touch_the_fit_did_not_resolve_is_the_fit_weighted_with_the_prior_never_called_determined(monkeypatch):
    # 1 s on PMMA: the fit has k and alpha, but not to 30 %. The posterior answer and the prior-given-e
    # switch (K_ALPHA_POSTERIOR False) on the same record: both flagged and not determined; the posterior's
    # rho c lies between the fit's and the prior's, its e is the touch's, its u(ln rho c) below the prior's.
    from edge.estimation import probe_estimate as pe
    from edge.physics.axisym import AxisymModel
    from edge.physics.geometry import PROBES
    from edge.physics.solids import Solid
    from tests.support.bundles import shipped_small_heater_estimator

    pmma = Solid(0.185, 1178.35, 1429.0)
    t = np.arange(51) * 0.02
    T, q = AxisymModel(PROBES["small-heater"], t).signals(pmma.k_W_mK, pmma.alpha_m2_s)
    rng = np.random.default_rng(3)
    T, q = T + 0.01 * rng.standard_normal(t.size), q + 0.5 * rng.standard_normal(t.size)
    axi = shipped_small_heater_estimator()
    # A calibrated probe (the posterior needs the calibration's terms in the fit's u): here the datasheet's,
    # known to 0.1 %.
    cal = (np.zeros(len(pe.CALIBRATED)), np.diag(np.full(len(pe.CALIBRATED), 1e-6)))
    post = axi.estimate(t, T, q, calibrated=cal)
    # Uncalibrated, the datasheet probe's fit is not weighted in: the prior given e, as the switch.
    assert "k_alpha_posterior" not in axi.estimate(t, T, q)["fit"]
    monkeypatch.setattr(pe, "K_ALPHA_POSTERIOR", False)
    prior = axi.estimate(t, T, q, calibrated=cal)
    assert post["effusivity_W_s05_m2K"] == prior["effusivity_W_s05_m2K"]
    for d in (post, prior):
        assert d["determined"] == ["e"] and d["from_prior"] == ["k", "alpha"]
        assert "k_alpha_from_prior" in d["flags"] and d["prior_reason"]
        assert d["k_W_mK"] ** 2 / d["alpha_m2_s"] == pytest.approx(d["effusivity_W_s05_m2K"] ** 2, rel=1e-9)
    p = post["fit"]["k_alpha_posterior"]
    assert "k_alpha_posterior" not in prior["fit"] and "data share" in post["prior_reason"]
    assert 0.0 < p["data_share"] < 1.0
    # The data did not determine k and alpha: the fit's own u (before the prior) is above the threshold.
    assert max(p["u_rel_fit"]["k"], p["u_rel_fit"]["alpha"]) >= axi.identifiable_u_rel
    ln_rc = {n: math.log(d["k_W_mK"] / d["alpha_m2_s"]) for n, d in (("post", post), ("prior", prior))}
    ln_rc_fit = math.log(p["fit_k_W_mK"] / p["fit_alpha_m2_s"])
    assert min(ln_rc_fit, ln_rc["prior"]) - 1e-9 <= ln_rc["post"] <= max(ln_rc_fit, ln_rc["prior"]) + 1e-9
    u_k, u_a = post["k_W_mK_u"] / post["k_W_mK"], post["alpha_m2_s_u"] / post["alpha_m2_s"]
    u_rc_post = math.sqrt(u_k ** 2 + u_a ** 2 - 2 * post["corr_k_alpha"] * u_k * u_a)
    e = post["effusivity_W_s05_m2K"]
    _, u_rc_prior, _ = axi.estimator.library.prior_rho_c(e, post["effusivity_W_s05_m2K_u"] / e)
    assert u_rc_post < u_rc_prior
