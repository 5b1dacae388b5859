import numpy as np
import pytest

from edge.physics import typek

# NIST ITS-90 type K table (mV, reference junction 0 °C), printed to 1 µV.
NIST_TABLE = [(-270, -6.458), (-200, -5.891), (-100, -3.554), (0, 0.000), (25, 1.000),
              (100, 4.096), (200, 8.138), (500, 20.644), (1000, 41.276), (1372, 54.886)]


@pytest.mark.parametrize("t_C, e_mV", NIST_TABLE)
def test_reference_function_matches_nist_table(t_C, e_mV):
    assert typek.emf_mV(t_C) == pytest.approx(e_mV, abs=0.0006)


def test_emf_is_vectorised_and_scalar_returns_float():
    t = np.array([[0.0, 25.0], [100.0, -100.0]])
    e = typek.emf_mV(t)
    assert e.shape == (2, 2)
    assert isinstance(typek.emf_mV(25.0), float)
    assert e[1, 0] == pytest.approx(4.096, abs=6e-4)


def test_inverse_round_trip_within_nist_accuracy():
    t_low = np.linspace(-200.0, 500.0, 1401)
    assert np.max(np.abs(typek.temperature_C(typek.emf_mV(t_low)) - t_low)) <= 0.05
    t_high = np.linspace(500.0, 1372.0, 873)
    # NIST states -0.05 .. +0.06 °C for the 500..1372 °C inverse.
    assert np.max(np.abs(typek.temperature_C(typek.emf_mV(t_high)) - t_high)) <= 0.06


def test_refined_inverse_is_exact():
    t = np.linspace(-200.0, 1372.0, 500)
    assert np.max(np.abs(typek.temperature_C(typek.emf_mV(t), refine=True) - t)) < 1e-6


def test_seebeck_at_zero_and_derivative_consistency():
    assert typek.seebeck_uV_per_K(0.0) == pytest.approx(39.45, abs=0.01)
    for t in (-150.0, 25.0, 300.0, 900.0):
        h = 1e-3
        num = (typek.emf_mV(t + h) - typek.emf_mV(t - h)) / (2 * h) * 1e3
        assert typek.seebeck_uV_per_K(t) == pytest.approx(num, rel=1e-6)


def test_cold_junction_compensation():
    # Thermocouple at 100 °C with terminals at 25 °C produces E(100) - E(25).
    e_meas = typek.emf_mV(100.0) - typek.emf_mV(25.0)
    assert typek.hot_junction_C(e_meas, 25.0, refine=True) == pytest.approx(100.0, abs=1e-6)
    out = typek.hot_junction_C(np.array([0.0, e_meas]), 25.0)
    assert out.shape == (2,) and out[0] == pytest.approx(25.0, abs=0.05)


@pytest.mark.parametrize("bad", [-270.1, 1372.5, np.nan])
def test_temperature_range_check(bad):
    with pytest.raises(ValueError, match="t_C"):
        typek.emf_mV(bad)


@pytest.mark.parametrize("bad", [-6.0, 55.0, np.inf])
def test_emf_range_check(bad):
    with pytest.raises(ValueError, match="e_mV"):
        typek.temperature_C(bad)


def test_array_with_one_bad_value_is_rejected():
    with pytest.raises(ValueError):
        typek.emf_mV([0.0, 2000.0])


def test_a_scalar_gives_the_array_paths_value_to_the_bit():
    # The drivers and emulators convert one sample at a time on a pure-Python path; it must be the
    # same arithmetic as the vectorised one, on every branch and at the branches' edges.
    rng = np.random.default_rng(7)
    t = np.r_[rng.uniform(typek.T_MIN_C, typek.T_MAX_C, 400), -270.0, -1e-9, 0.0, 126.9686, 1372.0]
    e = np.r_[rng.uniform(typek.INVERSE_E_MIN_MV, typek.E_MAX_MV, 400), typek.INVERSE_E_MIN_MV, -1e-9, 0.0,
              20.644, typek.E_MAX_MV]
    cj = rng.uniform(-20.0, 80.0, e.size)
    em = rng.uniform(-1.0, 5.0, e.size)
    for fn, x in ((typek.emf_mV, t), (typek.seebeck_uV_per_K, t), (typek.temperature_C, e),
                  (lambda v: typek.temperature_C(v, refine=True), e)):
        assert np.array_equal([fn(float(v)) for v in x], fn(x))
    assert np.array_equal([typek.hot_junction_C(float(a), float(b), refine=True) for a, b in zip(em, cj)],
                          typek.hot_junction_C(em, cj, refine=True))
    assert isinstance(typek.temperature_C(np.float64(1.0)), float)


@pytest.mark.parametrize("emf, cj, what", [(np.nan, 25.0, "emf_measured_mV"), (60.0, 25.0, "inverse range"),
                                           (1.0, 1400.0, "t_C")])
def test_cold_junction_compensation_names_what_is_wrong(emf, cj, what):
    with pytest.raises(ValueError, match=what):
        typek.hot_junction_C(emf, cj)
