"""The contact transient of an object at another temperature than the probe: the 1-D layered kernel.

A hand touch brings an object at ``T_obj`` onto a probe face at ``T_probe`` some time before the heater
starts.  By linearity the record is the heater's response (:mod:`edge.physics.axisym`) plus
``dT_obj = T_obj - T_probe`` times the *contact response*: the thermocouple's and the flux sensor's
answer to a probe at 0 meeting a semi-infinite object at 1 K at ``tau = 0``.  Over the probe's face the
contact is laterally uniform (the face is 80 mm across, the heat's reach in a touch a few mm), so the
kernel is the zero-Hankel-wavenumber limit of the same stack :class:`~edge.physics.axisym.AxisymModel`
models: substrate (insulated top) / heater film / sensing layer / contact resistance / object.  The
sensors' lateral averaging is then trivial; their depth averaging is kept (the flux sensor spans
``sensor_depth_m`` of the sensing layer).

In Laplace (``p``; ``gamma = sqrt(p / alpha)`` per layer), with ``Y = e sqrt(p)`` the object's surface
admittance, ``Y_o = Y / (1 + R_c Y)`` and ``Y_probe`` the stack's admittance seen from the contact
face, the face (thermocouple) temperature is ``theta_i = Y_o / (p (Y_o + Y_probe))`` and the flux into
the probe ``Y_probe theta_i``.  In the sensing layer (``x`` up from the face) the temperature is
``A exp(-gamma x) + B exp(-gamma (L - x))``: only decaying exponentials are formed, so nothing
overflows at large ``|gamma L|``.  Without a probe stack (``Y_probe`` of a half-space) this is the
exact two-half-space contact, ``theta_i = e_o / (e_o + e_p)`` for all t (tests/edge/physics).

Time inversion: the fixed hyperbolic contour of :class:`~edge.physics.axisym.HyperbolicInversion`
over the touch's ``[tau_min, tau_max]``.  Sign: the flux sensor reads downward flux (into the object)
as positive, as the heater's model does; a warmer object makes it negative.

Edge code: NumPy only.
"""

from __future__ import annotations

import numpy as np

from edge.checks import finite_array, finite_nonnegative, finite_positive
from edge.physics.axisym import HyperbolicInversion, insulated_layer_admittance, series_contact
from edge.physics.geometry import ProbeGeometry

__all__ = ["ContactKernel", "probe_admittance"]


def _layer_over(k: float, g: np.ndarray, d: float, Y_top: np.ndarray) -> np.ndarray:
    """Admittance seen from below a layer (k, gamma, thickness d) capped by admittance ``Y_top``."""
    kg = k * g
    rho = (kg - Y_top) / (kg + Y_top)
    E2 = np.exp(-2.0 * g * d)
    return kg * (1.0 - rho * E2) / (1.0 + rho * E2)


def probe_admittance(geometry: ProbeGeometry, p: np.ndarray) -> np.ndarray:
    """The stack's 1-D admittance (W/m^2/K in Laplace) seen from the contact face, heater film included."""
    g = geometry
    if g.substrate is None:
        Y = np.zeros_like(p)
    else:
        gf = np.sqrt(p / g.substrate.alpha_m2_s)
        Y = insulated_layer_admittance(g.substrate.k_W_mK, gf, g.substrate_thickness_m)
    hm = g.heater_material
    Y = _layer_over(hm.k_W_mK, np.sqrt(p / hm.alpha_m2_s), g.heater_thickness_m, Y)
    return Y   # the sensing layer is added by ContactKernel (its depth profile is read there)


class ContactKernel:
    """The contact response of one probe on the times of one touch (per kelvin of object - probe).

    Parameters
    ----------
    geometry : ProbeGeometry
        The probe (the calibrated one when a calibration identified it).
    tau_T_s, tau_q_s : array_like
        Times since contact (s) of the thermocouple's and the flux sensor's samples; times <= 0 give 0.
    n_laplace : int
        Nodes on the hyperbolic contour.
    """

    def __init__(self, geometry: ProbeGeometry, tau_T_s, tau_q_s, tau_h_s=None, *, n_laplace: int = 32) -> None:
        self.geometry = geometry
        tT = finite_array("tau_T_s", tau_T_s)
        tq = finite_array("tau_q_s", tau_q_s)
        th = np.zeros(0) if tau_h_s is None else finite_array("tau_h_s", tau_h_s)
        self.n_T, self.n_q = tT.size, tq.size
        self.tau_T_s, self.tau_q_s = tT, tq
        # ``tau_h_s``: times of the heater film's temperature (its resistance follows it: the heater's TCR).
        self.inversion = HyperbolicInversion.build(np.concatenate([tT, tq, th]), n_laplace)
        p = self.inversion.s
        self._p = p
        sm = geometry.sensing
        self._k_s = sm.k_W_mK
        self._g_s = np.sqrt(p / sm.alpha_m2_s)
        self._L = geometry.sensing_thickness_m
        self._Y_heater = probe_admittance(geometry, p)
        z0, z1 = geometry.sensor_depth_m
        # Depths are measured from the heater (z = 0) to the face (z = L): x = L - z from the face.
        self._x0, self._x1 = self._L - z1, self._L - z0
        self._sqrt_p = np.sqrt(p)

    def transforms(self, e_W_s05_m2K: float, contact_resistance_m2K_W: float = 0.0):
        """Laplace transforms (n_p,) of the thermocouple's, the flux sensor's and the heater film's response."""
        Yo = series_contact(e_W_s05_m2K * self._sqrt_p, contact_resistance_m2K_W)
        k, g, L = self._k_s, self._g_s, self._L
        kg = k * g
        rho = (kg - self._Y_heater) / (kg + self._Y_heater)
        E = np.exp(-g * L)
        Yp = kg * (1.0 - rho * E * E) / (1.0 + rho * E * E)
        th_i = Yo / (self._p * (Yo + Yp))
        # The sensing layer's profile: A exp(-g x) + B exp(-g (L - x)), B = A E rho, A (1 + rho E^2) = th_i.
        A = th_i / (1.0 + rho * E * E)
        B = A * E * rho
        x0, x1 = self._x0, self._x1
        # Upward flux k g (A exp(-g x) - B exp(-g (L - x))) averaged over [x0, x1]; the sensor reads downward.
        if x1 - x0 > 0:
            up = k * (A * (np.exp(-g * x0) - np.exp(-g * x1)) - B * (np.exp(-g * (L - x1)) - np.exp(-g * (L - x0))))
            up = up / (x1 - x0)
        else:
            up = kg * (A * np.exp(-g * x0) - B * np.exp(-g * (L - x0)))
        return th_i, -up, A * E * (1.0 + rho)

    def responses(self, e_W_s05_m2K: float, contact_resistance_m2K_W: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """(thermocouple K, flux sensor W/m^2) per kelvin of object - probe, at ``tau_T_s`` and ``tau_q_s``."""
        finite_positive("e_W_s05_m2K", e_W_s05_m2K)
        finite_nonnegative("contact_resistance_m2K_W", contact_resistance_m2K_W)
        T, q, _ = self.transforms(e_W_s05_m2K, contact_resistance_m2K_W)
        out = self.inversion.invert(np.stack([T, q]))
        return out[0][:self.n_T], out[1][self.n_T:self.n_T + self.n_q]

    def heater_response(self, e_W_s05_m2K: float, contact_resistance_m2K_W: float = 0.0) -> np.ndarray:
        """The heater film's temperature (K per kelvin of object - probe) at ``tau_h_s``."""
        th = self.transforms(e_W_s05_m2K, contact_resistance_m2K_W)[2]
        return self.inversion.invert(th[None, :])[0][self.n_T + self.n_q:]
