"""Attainable uncertainties of a touch from its Fisher information: the numbers behind probe design.

For a heater radius (or a whole :class:`~edge.physics.geometry.ProbeGeometry`),
a contact time, a material, the noise of the two sensors and the sampling
interval, :func:`attainable` returns the noise-only standard uncertainties
(Cramer-Rao bounds at the true values) of ln e, ln k and ln alpha when k,
alpha and the nuisances (the heater power scale, optionally the contact
resistance and the object's temperature -- a hand touch's unknowns) are all unknown and no prior is used:

    F = J^T J,   J = d(model / sigma) / d(ln k, ln alpha, ln P [, R_c] [, T_obj]),
    cov = F^-1,  u(ln e)^2 = g^T cov g with g = (1, -1/2, 0, ...).

The Jacobian is the axisymmetric model's exact one
(:meth:`edge.physics.axisym.AxisymModel.transforms`).  A relative u of a
few percent means the touch measures the quantity; tens of percent or more
means it does not (with the paper's heater only e is measured and k, alpha
rest on the library prior).  Nothing here asserts that a fit attains the
bound: bench/axisym_bench.py measures that on the reference model.

This is the function behind ``thermotouch design`` (host/cli/design.py).

Why aluminium's u(alpha) here is not the issue's (#11) 7.4 % (2 s) / 3.7 % (5 s)
-------------------------------------------------------------------------------
The issue's setting (k, alpha and the power unknown, 10 mK / 0.5 W/m^2,
20-ms samples, 5 mm heater) gives here u(alpha) = 26 % (2 s) / 19 % (5 s) on
pure aluminium (k 237) and 13 % / 8.5 % on the paper's aluminium alloy
(k 120.4).  Not a bug -- the parameterisation and the noise model are the
fitter's (:class:`edge.estimation.axifit.AxiFitter` reports the same u at
the same point, tests/edge/estimation/test_design.py) -- but a different
probe.  Investigated (time-boxed; ``attainable`` with modified geometries):

* on a metal, the information on alpha is almost all in the flux record:
  with the thermocouple alone u(alpha) is 500-1000 %; with the flux record
  alone 13-27 %.  So where and how the flux is read decides the number;
* this module's flux sensor is the configured FHF05-class thermopile: a
  10 x 10 mm square (equal-area radius 5.64 mm, wider than the 5 mm heater)
  averaging the axial flux through the whole 0.40 mm sensing layer.  Read at
  the sensing-layer/object interface instead (the flux into the object,
  0.39-0.40 mm, 0.5 mm radius), u(alpha) falls to 19 % / 10 % (aluminium)
  and 8.9 % / 4.5 % (alloy) -- the issue's 2:1 ratio between 2 s and 5 s,
  which the full-depth sensor does not show (1.4:1);
* which aluminium: pure aluminium's u(alpha) is twice the alloy's;
* a known power halves u(alpha) at 2 s on the interface sensor (4.3 %
  alloy) but changes little with the full-depth sensor;
* a 20 um sensing layer (a bare heater disk on the object) brings the alloy
  to 7.6 % / 5.5 % (2 s right, 5 s not).

No single variant reproduces both of the issue's numbers; the nearest (alloy,
flux read at the object's surface, power unknown: 8.9 % / 4.5 %) says the
issue's table assumed a flux measured at the object's surface, not through
the sensing layer.  The numbers this module gives are the ones for the
shipped geometry (:data:`edge.physics.geometry.PROBES`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from edge.checks import finite_positive
from edge.physics.axisym import AxisymModel
from edge.physics.geometry import PROBES, ProbeGeometry
from edge.physics.solids import Solid

__all__ = ["Design", "attainable", "covariance_ln_k_alpha", "scan_heater_radius"]


@dataclass(frozen=True)
class Design:
    """Noise-only standard uncertainties of ln e, ln k, ln alpha (~ relative u) and the k-alpha correlation."""

    heater_radius_m: float
    contact_time_s: float
    power_W: float
    u_rel_effusivity: float
    u_rel_k: float
    u_rel_alpha: float
    corr_k_alpha: float

    def to_dict(self) -> dict:
        return {k: (float(v) if math.isfinite(v) else None) for k, v in self.__dict__.items()}



def covariance_ln_k_alpha(F: np.ndarray) -> np.ndarray:
    """Covariance from a Fisher matrix whose first two parameters are ln k and ln alpha.

    A vanishing prior (sd 100 in ln k and ln alpha, i.e. no information) keeps F invertible
    when a large heater leaves the k-alpha direction undetermined: u(k), u(alpha) then come out
    as ~100 (reported as such), and u(e), which is determined, stays exact. The inverse is taken
    on the diagonally scaled matrix (the parameters' scales differ by orders of magnitude).
    Shared by the design (:func:`attainable`) and the fit (:mod:`edge.estimation.axifit`).
    """
    F = np.array(F, float)
    F[0, 0] += 1e-4
    F[1, 1] += 1e-4
    d = np.sqrt(np.diag(F))
    try:
        return np.linalg.inv(F / np.outer(d, d)) / np.outer(d, d)
    except np.linalg.LinAlgError:
        return np.full(F.shape, np.inf)

def attainable(solid: Solid, contact_time_s: float, *, probe: ProbeGeometry | str = "small-heater",
               heater_radius_m: float | None = None, dt_s: float = 0.02, sigma_T_K: float = 0.01,
               sigma_q_W_m2: float = 0.5, power_W: float | None = None, fit_contact: bool = False,
               contact_resistance_m2K_W: float = 0.0, model: AxisymModel | None = None,
               fit_object_temperature: bool = False, contact_lead_s: float = 0.0) -> Design:
    """Attainable u(e), u(k), u(alpha) of one touch (see the module docstring).

    Parameters
    ----------
    solid : Solid
        The material touched (semi-infinite).
    contact_time_s : float
        Length of the record; samples every ``dt_s`` from ``dt_s`` on.
    probe : ProbeGeometry or str
        The probe (a name in :data:`PROBES`).
    heater_radius_m : float, optional
        Replace the probe's heater radius (same areal power, see
        :meth:`ProbeGeometry.with_heater_radius`).
    sigma_T_K, sigma_q_W_m2 : float
        Noise (1 sigma, white) of the thermocouple and the flux sensor.
    power_W : float, optional
        Heater power (default: the probe's nominal one).
    fit_contact : bool
        Count the contact resistance among the unknowns.
    model : AxisymModel, optional
        A prebuilt model for this probe and these times.
    fit_object_temperature : bool
        Count the object's temperature among the unknowns (a hand touch: the object is not at the
        probe's temperature).  After the contact transient it is a constant offset of the
        thermocouple's record (the sensor chain's fit has it as its first column,
        :func:`edge.estimation.sensor_chain.chain_design`); the flux record does not see it.
    contact_lead_s : float
        With ``fit_object_temperature``: the probe rests on the object this long before heating;
        those samples (from :data:`edge.estimation.chain_estimate.FIT_START_s` after contact, as the
        chain fits them) see the offset alone and pin it.
    """
    g = PROBES[probe] if isinstance(probe, str) else probe
    if heater_radius_m is not None:
        g = g.with_heater_radius(heater_radius_m)
    T_end = finite_positive("contact_time_s", contact_time_s)
    dt = finite_positive("dt_s", dt_s)
    t = dt * np.arange(1, int(math.floor(T_end / dt + 1e-9)) + 1)
    m = model if model is not None else AxisymModel(g, t)
    P = g.nominal_power_W if power_W is None else finite_positive("power_W", power_W)
    T, q, dT, dq = m.transforms(solid.k_W_mK, solid.alpha_m2_s, derivatives=True,
                                contact_resistance_m2K_W=contact_resistance_m2K_W)
    n_par = 3 if fit_contact else 2
    y = m.inversion.invert(np.concatenate([[T, q], dT[:n_par], dq[:n_par]]))
    wT, wq = P / sigma_T_K, P / sigma_q_W_m2
    cols = [np.concatenate([y[2 + j] * wT, y[2 + n_par + j] * wq]) for j in range(n_par)]
    cols.append(np.concatenate([y[0] * wT, y[1] * wq]))  # d / d ln P
    if fit_contact:
        cols[2] = cols[2] * 1e-4  # R_c in units of 1e-4 m^2 K/W keeps F well scaled
    if fit_object_temperature:
        # Samples in contact before heating (the chain fits from 0.3 s after contact): the offset alone.
        lead = max(float(contact_lead_s) - 0.3, 0.0)
        n_lead = int(math.floor(lead / dt + 1e-9))
        cols = [np.concatenate([np.zeros(n_lead), c]) for c in cols]
        cols.append(np.concatenate([np.full(n_lead + t.size, 1.0 / sigma_T_K), np.zeros(t.size)]))   # per K
    J = np.stack(cols, axis=1)
    cov = covariance_ln_k_alpha(J.T @ J)
    gvec = np.zeros(cov.shape[0])
    gvec[0], gvec[1] = 1.0, -0.5

    def sd(v):
        return math.sqrt(v) if v >= 0 and math.isfinite(v) else math.inf

    u_k, u_a = sd(cov[0, 0]), sd(cov[1, 1])
    corr = cov[0, 1] / (u_k * u_a) if math.isfinite(u_k * u_a) and u_k * u_a > 0 else math.nan
    return Design(heater_radius_m=g.heater_radius_m, contact_time_s=float(t[-1]), power_W=P,
                  u_rel_effusivity=sd(float(gvec @ cov @ gvec)), u_rel_k=u_k, u_rel_alpha=u_a,
                  corr_k_alpha=float(corr))


def scan_heater_radius(solid: Solid, contact_time_s: float, radii_m, **kw) -> list[Design]:
    """:func:`attainable` over heater radii (same areal power): where the k/alpha bound is lowest."""
    return [attainable(solid, contact_time_s, heater_radius_m=float(r), **kw) for r in radii_m]
