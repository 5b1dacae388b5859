"""The running decisions' cost per touch does not grow with the sample rate (issue #34 item 5: 50 Hz by default).

A refitting decision (the calibrated chain's, the small heater's) refits on a clock of heating time, not
per sample: at 50 Hz it makes the same refits per touch as at 10 Hz, each on the record so far.
"""

from __future__ import annotations

import pytest

from edge.estimation.running import CHAIN_EVERY_s, RefitDecision
from edge.recognition import ObjectSet


class CountingDecision(RefitDecision):
    """A refit that only records how many samples it was given."""

    def _refit(self, t_s):
        ts = self._record[0]
        self.sizes.append(len(ts))
        return self.answer


def _run(rate_Hz: float, heat_s: float = 2.0) -> CountingDecision:
    d = CountingDecision(ObjectSet.from_library(), 0.95, 0.3, every_s=CHAIN_EVERY_s, timer=lambda: 0.0)
    d.sizes = []
    ts: list = []
    d._record = (ts,)   # what attach_record of the chain / estimator decisions stores (the record lists)
    for k in range(1, int(heat_s * rate_Hz) + 1):
        ts.append(k / rate_Hz)
        d.update(k / rate_Hz, 1.0, 1000.0)
    return d


def test_refits_per_touch_are_set_by_heating_time_not_by_the_rate():
    slow, fast = _run(10.0), _run(50.0)
    # From 0.3 s to 2 s, one refit per CHAIN_EVERY_s (to within the sample a refit falls on).
    want = (2.0 - 0.3) / CHAIN_EVERY_s + 1
    assert slow.fits == pytest.approx(want, abs=1) and fast.fits == pytest.approx(want, abs=1)
    # Each refit sees the whole record so far: 5 x the samples at 50 Hz, never more refits.
    assert fast.sizes[-1] == 100 and slow.sizes[-1] == 20
