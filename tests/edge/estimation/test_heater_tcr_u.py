"""The calibrated heater TCR's own u in the answers' u, and as the object offset's TCR prior (issue #34)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from edge.estimation.object_offset import HEATER_TCR_PER_K, ObjectOffset
from edge.physics.axisym import AxisymModel
from edge.physics.geometry import PROBES
from edge.physics.solids import Solid
from tests.support.bundles import shipped_small_heater_estimator

G = PROBES["small-heater"]
PMMA = Solid(0.185, 1178.35, 1429.0)


@pytest.fixture(scope="module")
def axi():
    return shipped_small_heater_estimator()


@pytest.fixture(scope="module")
def touch():
    rng = np.random.default_rng(34)
    t = np.arange(1, 251) * 0.02
    T, q = AxisymModel(G, t).signals(PMMA.k_W_mK, PMMA.alpha_m2_s)
    return t, T + 0.01 * rng.standard_normal(t.size), q + 0.5 * rng.standard_normal(t.size)


def test_the_answers_u_grows_with_the_calibrated_tcrs_u(axi, touch):
    t, T, q = touch
    runs = [axi.estimate(t, T, q, heater_tcr_per_K=2.5e-3, heater_tcr_per_K_u=u) for u in (0.0, 0.4e-3, 0.8e-3)]
    assert "u_rel_heater_tcr" not in runs[0]["fit"]
    for key in ("k_W_mK", "alpha_m2_s", "effusivity_W_s05_m2K"):
        u = [d[key + "_u"] / d[key] for d in runs]
        assert u[0] < u[1] < u[2], key
        assert runs[0][key] == runs[1][key]            # the u, not the answer
    # Linearised: the response to twice the TCR's u is twice the response.
    g1, g2 = runs[1]["fit"]["u_rel_heater_tcr"], runs[2]["fit"]["u_rel_heater_tcr"]
    assert g1["k"] > 0 and g2["k"] == pytest.approx(2 * g1["k"], rel=1e-6)
    with pytest.raises(ValueError):
        axi.estimate(t, T, q, heater_tcr_per_K=2.5e-3, heater_tcr_per_K_u=-1e-4)


def test_the_tcr_response_predicts_the_fits_shift_for_a_wrong_tcr(axi, touch):
    # Records made with alpha_R = 2.5e-3 /K fitted with 2.0e-3: the fit moves by about the linearised response.
    t, T, q = touch
    fitted = axi.estimate(t, T, q, heater_tcr_per_K=2.5e-3)
    wrong = axi.estimate(t, T, q, heater_tcr_per_K=2.0e-3, heater_tcr_per_K_u=0.5e-3)
    shift = abs(math.log(wrong["fit"]["k_W_mK"] / fitted["fit"]["k_W_mK"]))
    assert shift == pytest.approx(wrong["fit"]["u_rel_heater_tcr"]["k"], rel=0.3)


def test_the_offsets_tcr_prior_is_the_calibrated_one_when_given(axi):
    class _Kernel:
        n_T = n_q = 3

    beta = np.array([1.0, 0.0, 0.0, 2.0, -0.005])
    lo, hi = HEATER_TCR_PER_K
    row, _ = ObjectOffset(_Kernel(), 0, np.arange(1, 4)).prior(beta)
    assert row[0, 3] / row[0, -1] == pytest.approx(0.5 * (lo + hi))
    assert 1.0 / row[0, -1] == pytest.approx((hi - lo) / math.sqrt(12.0) * 2.0)
    row, _ = ObjectOffset(_Kernel(), 0, np.arange(1, 4), (2.2e-3, 0.4e-3)).prior(beta)
    assert row[0, 3] / row[0, -1] == pytest.approx(2.2e-3)
    assert 1.0 / row[0, -1] == pytest.approx(0.4e-3 * 2.0)
