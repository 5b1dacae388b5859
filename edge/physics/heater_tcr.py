"""The heater film's TCR under its own heating: the first-order power droop and its response.

At constant voltage the film's power is ``P = V^2 / (R0 (1 + alpha_R dT_h))``, ``dT_h`` the film's own
temperature rise; to first order ``P(t) = P0 (1 - alpha_R P0 h(t))`` with ``h`` the film's mean
temperature per watt (:meth:`edge.physics.axisym.AxisymModel.heater_transform`).  Every record is the
convolution of its impulse response with the power, so in Laplace (``T`` the step response per watt)

    y(p) = P0 T(p) - alpha_R P0^2 p T(p) H(p):

the droop is one more column, ``p T H`` (inverted on the same contour), with coefficient ``-alpha_R P0^2``.
Left out, the calibration bends the probe's stack to absorb the droop (a drawn probe's substrate k came
out +67 %, issue #34).  Edge code: NumPy only.
"""

from __future__ import annotations

import numpy as np

__all__ = ["droop_transforms"]


def droop_transforms(model, k_W_mK: float, alpha_m2_s: float, T: np.ndarray, q: np.ndarray, *,
                     thickness_m: float | None = None, back: str = "infinite",
                     contact_resistance_m2K_W: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(p T H, p q H, p H): the droop's columns' transforms per unit ``alpha_R P0^2`` and their common factor.

    ``T``, ``q``: the thermocouple's and flux sensor's step-response transforms per watt on ``model``'s
    contour (:meth:`~edge.physics.axisym.AxisymModel.transforms`).
    """
    H = model.heater_transform(k_W_mK, alpha_m2_s, thickness_m=thickness_m, back=back,
                               contact_resistance_m2K_W=contact_resistance_m2K_W)
    pH = model.inversion.s * H
    return pH * T, pH * q, pH
