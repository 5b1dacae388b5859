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
