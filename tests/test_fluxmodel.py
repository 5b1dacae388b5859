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
    assert rel_err(surface_temperature(r.t_s, r.q_f_W_m2, solid, scheme="paper"), ref) < 1e-2


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
