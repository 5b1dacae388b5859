"""The running decision through the calibrated sensor chain (a real probe's ``--until-decided``).

:class:`~edge.estimation.running.SequentialDecision` fits the thick-body
model to the raw thermopile reading: right for the flux at the object's
face, wrong for a thermopile inside its sensing layer, which for the first
second or two reads heat still warming the layer (on the faithful world a
PMMA touch read as glass).  With a calibration installed the device's
answer is the calibrated chain's (:func:`edge.estimation.seam.chain_answer`);
:class:`ChainDecision` makes the running answer the same estimate, on the
record so far: :func:`edge.estimation.chain_estimate.estimate_from_contact`
from the contact on (object temperature and contact resistance free), every
``every_s`` of heating, and no answer while the chain flags that it does
not describe the record.  It needs the samples since arming, not only the
heating ones: the sequence hands it its record lists (:meth:`attach_record`).

NumPy only (edge runtime).
"""

from __future__ import annotations

import time
from typing import Any, Callable

import numpy as np

from edge.estimation.chain_estimate import estimate_from_contact
from edge.estimation.running import RefitDecision, RunningAnswer
from edge.estimation.seam import BLOCKERS

__all__ = ["ChainDecision", "CHAIN_EVERY_s"]

#: Heating time between two chain fits: about 6 ms each on this machine (bench/daemon_bench.py), so a
#: fit per 0.1 s keeps the sampling loop's budget on a Pi-class CPU.
CHAIN_EVERY_s = 0.1


class ChainDecision(RefitDecision):
    """Sequential decision on the calibrated sensor chain's running estimate.

    Parameters
    ----------
    object_set, threshold, min_time_s
        As for :class:`~edge.estimation.running.SequentialDecision`.
    calibration : ProbeCalibration
        The installed calibration (the chain's parameters and their u).
    every_s : float
        Heating time between fits (:data:`CHAIN_EVERY_s`), stretched where a fit takes more than its
        share (:class:`~edge.estimation.running.RefitCadence`).
    timer : callable
        Wall-clock seconds for the cadence (tests pass their own).
    """

    source = "sensor_chain"

    def __init__(self, object_set: Any, threshold: float, min_time_s: float, *, calibration: Any,
                 every_s: float = CHAIN_EVERY_s, timer: Callable[[], float] = time.perf_counter) -> None:
        super().__init__(object_set, threshold, min_time_s, every_s=every_s, timer=timer)
        self.calibration = calibration

    def attach_record(self, t_s: list, T_C: list, q_W_m2: list, t_on_s: float, **_baseline: Any) -> None:
        """The sequence's record lists (appended in place; absolute clock times) and the heater-on time.

        The chain fits from the contact on, with the object's temperature free: the baseline the
        sequence also passes (``T0_C``, ``q0_W_m2``, ``dts``) is not used.
        """
        self._record = (t_s, T_C, q_W_m2, float(t_on_s))

    def _refit(self, t_s: float) -> RunningAnswer | None:
        ts, Ts, qs, t_on = self._record
        n = min(len(ts), len(Ts), len(qs))
        try:
            d = estimate_from_contact(np.asarray(ts[:n], float) - t_on, np.asarray(Ts[:n], float),
                                      np.asarray(qs[:n], float), self.calibration)
        except ValueError:  # a prefix the chain cannot fit yet (too few samples since contact)
            return self.answer
        u_ln_e = self.u_ln_e(d.get("effusivity_W_s05_m2K"), d.get("effusivity_W_s05_m2K_u"))
        if u_ln_e is None or BLOCKERS & set(d.get("flags") or ()):   # the one blocker table
            return self.answer
        return self._answer(t_s, float(d["effusivity_W_s05_m2K"]), u_ln_e, n)
