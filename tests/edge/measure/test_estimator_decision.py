"""EstimatorDecision: the running answer as the device estimator's refit of the record so far."""

from __future__ import annotations

import numpy as np
import pytest

from edge.recognition import KnownObject, ObjectSet
from edge.estimation.running import EstimatorDecision

P = KnownObject.from_properties
SET = ObjectSet([P("pmma", "polymer", 0.185, 1178.35, 1429), P("glass", "glass", 1.0, 2500, 750),
                 P("steel", "alloy", 17, 7900, 500)])
GLASS_E = (1.0 * 2500 * 750) ** 0.5
RATE_Hz = 50.0


class FakeEstimator:
    """Records what it is asked; answers glass with a u shrinking like 1/sqrt(samples)."""

    def __init__(self, flags=(), fail_below: int = 0):
        self.calls, self.prepared, self.flags, self.fail_below = [], [], list(flags), fail_below

    def prepare(self, t_s):
        self.prepared.append(np.array(t_s))

    def __call__(self, t_s, dT_K, q_W_m2, power_W, method):
        self.calls.append((np.array(t_s), np.array(dT_K), np.array(q_W_m2), power_W, method))
        if t_s.size < self.fail_below:
            raise ValueError("too short")
        return {"effusivity_W_s05_m2K": GLASS_E, "effusivity_W_s05_m2K_u": GLASS_E * 0.5 / np.sqrt(t_s.size),
                "flags": list(self.flags)}


def run(dec, heat_s=2.0, T0=25.0, q0=3.0):
    """Feed a touch sample by sample, as the sequence does: record lists grow, update on each sample."""
    ts, Ts, qs, dts = [], [], [], []
    t_on = 100.0
    for k in range(10):                      # baseline
        ts.append(t_on - 0.2 + 0.02 * k), Ts.append(T0), qs.append(q0), dts.append((0.0, 0.001))
    dec.attach_record(ts, Ts, qs, t_on, T0_C=T0, q0_W_m2=q0, dts=dts)
    answers = []
    for k in range(1, int(heat_s * RATE_Hz) + 1):
        t = k / RATE_Hz
        ts.append(t_on + t), Ts.append(T0 + 0.5 * np.sqrt(t)), qs.append(q0 + 800.0), dts.append((0.0, 0.001))
        answers.append(dec.update(t, Ts[-1] - T0, qs[-1] - q0))
        if dec.decided is not None:
            break
    return answers


def test_refits_the_resampled_record_at_most_once_per_interval_and_prepares_the_whole_grid():
    fn = FakeEstimator()
    # Two objects of one effusivity: the posterior stays near 1/2, so the touch runs its whole profile.
    twins = SET.with_object(P("glass_twin", "glass", 1.0, 2500, 750))
    dec = EstimatorDecision(twins, 0.9, 0.3, estimate_fn=fn, rate_Hz=RATE_Hz, heat_s=2.0, power_W=0.1,
                            method="default", every_s=0.25)
    run(dec)
    assert len(fn.prepared) == 1 and fn.prepared[0] == pytest.approx(np.arange(1, 101) / RATE_Hz)
    # From min_time_s on, once per 0.25 s: 0.3, 0.56, ... (a sample's grid), not once per sample.
    starts = [c[0][-1] for c in fn.calls]
    assert len(fn.calls) == dec.fits and 6 <= len(fn.calls) <= 8
    assert starts[0] == pytest.approx(0.3) and np.all(np.diff(starts) >= 0.25 - 1e-9)
    t, dT, q, power_W, method = fn.calls[-1]
    # Each refit sees the heating record as the result will: grid k / rate from heater-on, baseline removed.
    assert t == pytest.approx(np.arange(1, t.size + 1) / RATE_Hz)
    assert dT[-1] == pytest.approx(0.5 * np.sqrt(t[-1]), rel=1e-3) and q == pytest.approx(800.0)
    assert power_W == 0.1 and method == "default"   # the power itself (issue #33: no q_v round trip)
    ans = dec.answer
    assert ans.object in ("glass", "glass_twin") and ans.source == "device_estimate" and not ans.decided
    assert ans.n == t.size


def test_decides_at_the_threshold_after_the_minimum_time():
    fn = FakeEstimator()
    dec = EstimatorDecision(SET, 0.9, 0.5, estimate_fn=fn, rate_Hz=RATE_Hz, heat_s=2.0, power_W=0.1)
    run(dec)
    assert dec.decided is not None and dec.decided.object == "glass" and dec.decided.decided
    assert dec.decided.elapsed_s >= 0.5 and dec.decided.posterior >= 0.9


def test_a_slow_estimator_is_refitted_less_often_instead_of_delaying_the_samples():
    now = [0.0]

    class Slow(FakeEstimator):
        def __call__(self, *a):
            now[0] += 0.1         # 100 ms a fit, as on a slow CPU: 0.5 s between refits at most 20 %
            return super().__call__(*a)

    fast, slow = FakeEstimator(), Slow()
    twins = SET.with_object(P("glass_twin", "glass", 1.0, 2500, 750))
    for fn in (fast, slow):
        run(EstimatorDecision(twins, 0.9, 0.3, estimate_fn=fn, rate_Hz=RATE_Hz, heat_s=2.0, power_W=0.1,
                              every_s=0.25, timer=lambda: now[0]))
    starts = [c[0][-1] for c in slow.calls]
    # After the first refit (one-time costs are not a measure), 100 ms a refit -> 0.5 s apart.
    assert np.all(np.diff(starts[1:]) >= 0.5 - 1e-9) and len(slow.calls) < len(fast.calls)


@pytest.mark.parametrize("flags", [["insufficient_signal"], ["no_contact"], ["not_converged"]])
def test_an_estimate_that_says_nothing_yet_gives_no_answer(flags):
    fn = FakeEstimator(flags=flags)
    dec = EstimatorDecision(SET, 0.9, 0.3, estimate_fn=fn, rate_Hz=RATE_Hz, heat_s=1.0, power_W=0.1)
    answers = run(dec, heat_s=1.0)
    assert fn.calls and all(a is None for a in answers) and dec.decided is None


def test_an_estimate_without_its_uncertainty_gives_no_answer():
    class NoU(FakeEstimator):
        def __call__(self, *a):
            d = super().__call__(*a)
            d["effusivity_W_s05_m2K_u"] = None
            return d

    fn = NoU()
    dec = EstimatorDecision(SET, 0.5, 0.3, estimate_fn=fn, rate_Hz=RATE_Hz, heat_s=1.0, power_W=0.1)
    answers = run(dec, heat_s=1.0)
    assert fn.calls and all(a is None for a in answers)


def test_a_prefix_the_estimator_cannot_fit_yet_is_skipped_and_the_next_one_answers():
    fn = FakeEstimator(fail_below=20)
    dec = EstimatorDecision(SET, 1.0, 0.3, estimate_fn=fn, rate_Hz=RATE_Hz, heat_s=1.0, power_W=0.1)
    answers = run(dec, heat_s=1.0)
    assert answers[int(0.3 * RATE_Hz) - 1] is None and answers[-1] is not None and answers[-1].object == "glass"


def test_needs_the_baseline_and_valid_parameters():
    dec = EstimatorDecision(SET, 0.9, 0.3, estimate_fn=FakeEstimator(), rate_Hz=RATE_Hz, heat_s=1.0, power_W=0.1)
    with pytest.raises(ValueError, match="baseline"):
        dec.attach_record([], [], [], 0.0)
    with pytest.raises(ValueError, match="rate_Hz"):
        EstimatorDecision(SET, 0.9, 0.3, estimate_fn=FakeEstimator(), rate_Hz=0.0, heat_s=1.0, power_W=0.1)
    assert dec.update(0.5, 0.1, 100.0) is None     # no record attached: nothing to refit
