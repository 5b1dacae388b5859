"""A hand touch's object offset on the small-heater probe: the linear nuisances of the axisymmetric fit.

A hand brings the object onto the probe 0.5-3 s before heating, at up to +-3 K from the probe; the
record is the heater's response plus ``dT_obj`` times the contact response
(:class:`edge.physics.contact_offset.ContactKernel`).  :class:`ObjectOffset` gives
:class:`~edge.estimation.axifit.AxiFitter` its linear nuisance columns -- the probe's own temperature
(a constant on the thermocouple), the flux channel's zero (a constant on the flux sensor), the offset,
and the heater's TCR cross term (the contact transient moves the heater film's temperature, so its
resistance and, at constant voltage, its power) with a prior on its coefficient -- over the samples
from the contact to heater-off (:func:`pre_heating` takes the ones before heater-on from the raw record).

Edge code: NumPy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from edge.estimation.axifit import _RC_UNIT

__all__ = ["PreHeating", "pre_heating", "ObjectOffset", "STACK_TOLERANCE", "HEATER_TCR_PER_K"]

#: What the offset's kernel takes the stack to be known to (relative sd, index in :data:`CALIBRATED`): the
#: datasheet tolerances of the sensing layer's thickness and k (+-10 %) and the substrate foam's k (+-20 %)
#: and rho c (+-15 %), uniform (sd = half-width / sqrt 3).
STACK_TOLERANCE = {1: 0.10 / math.sqrt(3.0), 2: 0.10 / math.sqrt(3.0), 3: 0.20 / math.sqrt(3.0),
                   4: 0.15 / math.sqrt(3.0)}


#: Take the offset kernel's stack as known to the calibration's covariance (True) or to the datasheet's
#: tolerances (False, :data:`STACK_TOLERANCE`). With the heater's TCR in the calibration the identified stack
#: is near the drawn one (bench/asbuilt_small_bench.py: substrate k within 6 % in median, was 22 %); the
#: calibration stated the flux scale's and the sensing layer's u ~3 x too small (rms z 2.6-3.4 over 7 drawn
#: probes) until it carried the drawing's unfitted tolerances as model-form terms
#: (edge.calibration.axi.MODEL_FORM_TOLERANCES; rms z 1.5 / 0.7 / 0.7). Bench: ``--offset-stack datasheet``.
OFFSET_STACK_FROM_CALIBRATION = True


#: Samples this soon after the contact instant are not fitted (s): the contact finder places the instant
#: within a sample period, and a hand's first touch is not a perfect step (as the sensor chain's fit start).
OFFSET_FIT_START_s = 0.2
#: Air before the contact that pins the probe's own temperature and the flux channel's zero (s).
OFFSET_AIR_s = 1.0
#: Heating-grid samples before this (s) are not fitted with the offset model: the grid is anchored at (0, 0)
#: (edge.estimation.conditioning.resample_uniform), which assumes a flat baseline, and a contact transient is not.
OFFSET_GRID_START_s = 0.05
#: The heater film's temperature coefficient of resistance the device assumes (1/K): film heaters' range
#: (NiCr / carbon films; constantan ~0); uniform over it, its sd is the prior's.
HEATER_TCR_PER_K = (0.001, 0.004)
#: Model the heater's TCR cross term of the offset (:class:`ObjectOffset`).
OFFSET_TCR = True
#: Step (in ln e) of the finite difference of the contact response.
_LN_E_STEP = 1e-4
#: Step of R_c (m^2K/W) of the same.
_RC_STEP = 1e-7


@dataclass(frozen=True)
class PreHeating:
    """A touch's samples from before heater-on, for the object-offset model (:class:`ObjectOffset`).

    ``t_s``: the samples' times (s, < 0, on the record's clock: 0 at heater-on); ``tau_T_s`` /
    ``tau_q_s``: the thermocouple's and the flux sensor's read times since the contact instant;
    ``dT_K`` / ``q_W_m2``: the readings less the same baseline the heating grid has; ``contact_t_s``:
    the contact instant on the record's clock.
    """

    t_s: np.ndarray
    tau_T_s: np.ndarray
    tau_q_s: np.ndarray
    dT_K: np.ndarray
    q_W_m2: np.ndarray
    contact_t_s: float


def pre_heating(record, T0_C: float, q_offset_W_m2: float) -> PreHeating | None:
    """The pre-heating samples of a hand touch whose contact the record holds, or None.

    None when the record did not start in air or no contact step was seen before heater-on (an object
    at the probe's temperature: nothing to model, :func:`edge.estimation.contact.find_contact`).
    """
    from edge.estimation.contact import find_contact  # noqa: PLC0415 - same package, a leaf

    t, T, q = (np.asarray(x, float) for x in (record.t_s, record.T_C, record.q_W_m2))
    if record.heater_on_t_s is None or t.size < 8:
        return None
    try:
        c = find_contact(t, T, q)
    except ValueError:
        return None
    if not (c.detected and c.recorded_in_air and c.how in ("temperature", "flux")):
        return None
    # The true instant lies within the sample period after the last sample in air.
    t_c = float(c.t_s) + 0.5 / float(record.sample_rate_Hz)
    tau = t - t_c
    keep = (t < 0) & (((tau < 0) & (tau >= -OFFSET_AIR_s)) | (tau >= OFFSET_FIT_START_s))
    if np.count_nonzero(keep & (tau < 0)) < 3:
        return None
    dTt = np.zeros_like(t) if record.T_dt_s is None else np.asarray(record.T_dt_s, float)
    dqt = np.zeros_like(t) if record.q_dt_s is None else np.asarray(record.q_dt_s, float)
    return PreHeating(t_s=t[keep], tau_T_s=(tau + dTt - record.T_age_s)[keep], tau_q_s=(tau + dqt)[keep],
                      dT_K=T[keep] - T0_C, q_W_m2=q[keep] - q_offset_W_m2, contact_t_s=t_c)


class ObjectOffset:
    """Linear nuisances of a hand touch for :class:`~edge.estimation.axifit.AxiFitter`: the probe's own
    temperature (a constant on the thermocouple), the flux channel's zero (a constant on the flux
    sensor) and the object's offset ``T_obj - T_probe`` (times the contact response,
    :class:`edge.physics.contact_offset.ContactKernel`, which depends on the object's e and R_c).
    """

    names = ("probe_temperature_K", "flux_zero_W_m2", "object_offset_K")
    def __init__(self, kernel, n_pre: int = 0, grid_k=None,
                 tcr_prior_per_K: tuple[float, float] | None = None) -> None:
        self.kernel = kernel
        #: The TCR's prior (mean, standard u; 1/K): the calibration's alpha_R +- u when it identified one,
        #: else the film heaters' range (:data:`HEATER_TCR_PER_K`, uniform).
        lo, hi = HEATER_TCR_PER_K
        self.tcr_prior_per_K = ((0.5 * (lo + hi), (hi - lo) / math.sqrt(12.0)) if tcr_prior_per_K is None
                                else (float(tcr_prior_per_K[0]), float(tcr_prior_per_K[1])))
        self.n_T = kernel.n_T
        self.n_q = kernel.n_q
        #: The heater's TCR: the contact transient moves the heater film's temperature, so its resistance
        #: and, at constant voltage, its power: P0 (1 - alpha_R dT_obj g_h(t - t_c)). Its coefficient
        #: (-alpha_R dT_obj; alpha_R 0.001-0.004 /K on film heaters, unknown to the device) is one more
        #: linear nuisance, its column the heater's response to that power change (a convolution on the grid).
        self.tcr = grid_k is not None
        if not self.tcr:
            self.prior = None     # nothing to constrain
        self.n_pre = int(n_pre)
        self.grid_k = None if grid_k is None else np.asarray(grid_k, int)

    def prior(self, beta: np.ndarray):
        """The TCR coefficient's prior given the offset: -alpha_R dT_obj, alpha_R from :attr:`tcr_prior_per_K`.

        One row over the linear coefficients (power scale, probe temperature, flux zero, offset, TCR):
        ``(c + alpha_mid dT) / (alpha_sd |dT|)`` with dT the unconstrained fit's (its scale, held fixed).
        """
        mid, sd = self.tcr_prior_per_K
        sd = max(sd, 1e-6)   # a calibrated alpha_R known "exactly" would make the row singular
        width = sd * max(abs(float(beta[3])), 0.05)
        row = np.zeros((1, beta.size))
        row[0, 3], row[0, -1] = mid / width, 1.0 / width
        return row, np.zeros(1)

    def _g(self, e: float, R: float) -> np.ndarray:
        T, q, _ = self.kernel.transforms(e, R)
        return self.kernel.inversion.invert(np.stack([T, q]))

    def _conv(self, m: np.ndarray, d_eps: np.ndarray) -> np.ndarray:
        """sum_k H((i - k + 1/2) dt) d_eps_k at the heating rows; H: the heater column on the grid (0 before)."""
        N = d_eps.size
        H = np.zeros(N + 1)
        H[self.grid_k] = m[self.n_pre:]
        Hm = 0.5 * (H[:-1] + H[1:])
        full = np.convolve(Hm, d_eps)[:N]           # index i-1 <-> grid k = i
        out = np.zeros(m.size)
        out[self.n_pre:] = full[self.grid_k - 1]
        return out

    def tcr_columns(self, k: float, alpha: float, R: float, mT, mq, dmT, dmq, jac: bool):
        """The TCR column (weighted like the heater's) and its theta-derivatives (npar, n) or None."""
        e = k / math.sqrt(alpha)
        d_eps = np.diff(self.kernel.heater_response(e, R))
        xT, xq = self._conv(mT, d_eps), self._conv(mq, d_eps)
        if not jac:
            return np.concatenate([xT, xq]), None
        de = np.diff(self.kernel.heater_response(e * math.exp(_LN_E_STEP), R)) - d_eps
        dR = np.diff(self.kernel.heater_response(e, R + _RC_STEP)) - d_eps
        rows = []
        for i in range(dmT.shape[0]):
            # R_c's derivative in the fitter's unit of R_c (as its heater columns').
            dd = (de / _LN_E_STEP, -0.5 * de / _LN_E_STEP, dR / _RC_STEP * _RC_UNIT)[i]
            rows.append(np.concatenate([self._conv(dmT[i], d_eps) + self._conv(mT, dd),
                                        self._conv(dmq[i], d_eps) + self._conv(mq, dd)]))
        return np.concatenate([xT, xq]), np.stack(rows)

    def columns(self, k: float, alpha: float, R: float, jac: bool):
        e = k / math.sqrt(alpha)
        g = self._g(e, R)
        nT, nq = self.n_T, self.n_q
        XT = np.stack([np.ones(nT), np.zeros(nT), g[0][:nT]])
        Xq = np.stack([np.zeros(nq), np.ones(nq), g[1][nT:nT + nq]])
        m = 3
        if not jac:
            return XT, Xq, None, None
        dge = (self._g(e * math.exp(_LN_E_STEP), R) - g) / _LN_E_STEP
        dgR = (self._g(e, R + _RC_STEP) - g) / _RC_STEP
        dXT, dXq = np.zeros((3, m, nT)), np.zeros((3, m, nq))
        for i, d in enumerate((dge, -0.5 * dge, dgR)):   # d / d(ln k, ln alpha, R_c); e = k / sqrt(alpha)
            dXT[i, 2], dXq[i, m - 1] = d[0][:nT], d[1][nT:nT + nq]
        return XT, Xq, dXT, dXq
