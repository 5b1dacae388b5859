"""The material library as the device holds it: a prior on ρc given e, and naming a material.

A bundle carries the library as plain arrays (``lib_*``); :class:`Library`
turns them into the two things an estimate needs from it:

* :meth:`Library.prior_rho_c` -- one touch on a thick body determines the
  effusivity e only, so k and α need ln(ρc); the library's materials near the
  measured e, weighted by how well e matches, give its mean and spread;
* :meth:`Library.identify` -- the library's materials ranked by the
  likelihood of the measured e, normalised to probabilities.
"""

from __future__ import annotations

import math
from typing import Mapping

import numpy as np

__all__ = ["Library", "OUTSIDE_FACTOR", "loo_rho_c_intrinsic_ln"]

#: An e beyond this factor of the library's range is flagged as outside it (the prior extrapolates).
OUTSIDE_FACTOR = 1.5


def _kernel_moments(ln_e: np.ndarray, ln_e_lib: np.ndarray, ln_rc_lib: np.ndarray, width: float,
                    exclude_self: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Kernel-weighted mean and variance of the library's ln ρc at each ``ln_e`` (Gaussian kernel in ln e).

    ``exclude_self``: query i is library entry i, left out of its own moments (leave-one-out).
    """
    z2 = ((ln_e[:, None] - ln_e_lib[None, :]) / width) ** 2
    if exclude_self:
        np.fill_diagonal(z2, np.inf)
    w = np.exp(-0.5 * (z2 - np.min(z2, axis=1, keepdims=True)))
    sw = np.sum(w, axis=1)
    mean = np.sum(w * ln_rc_lib, axis=1) / sw
    var = np.sum(w * (ln_rc_lib - mean[:, None]) ** 2, axis=1) / sw
    return mean, var


def loo_rho_c_intrinsic_ln(effusivity, rho_c, *, kernel_floor_ln: float) -> float:
    """The ``rho_c_intrinsic_ln`` that makes the prior's stated spread true on the library itself.

    Each material is left out in turn and its ln ρc predicted from the others at its own e;
    the intrinsic spread is the value at which these leave-one-out residuals, divided by the
    prior's stated standard deviation, have unit mean square (bisection: the mean square falls
    monotonically as the spread grows). 0 when the kernel's own local variance already covers
    them. A prior whose intervals did not cover the library's own materials would state k and α
    better than the library knows them.
    """
    ln_e, ln_rc = np.log(np.asarray(effusivity, float)), np.log(np.asarray(rho_c, float))
    if ln_e.size < 3:
        raise ValueError("a leave-one-out spread needs at least 3 materials")
    mean, var = _kernel_moments(ln_e, ln_e, ln_rc, float(kernel_floor_ln), exclude_self=True)
    r2 = (ln_rc - mean) ** 2

    def ms(s: float) -> float:
        return float(np.mean(r2 / (var + s * s)))

    lo, hi = 0.0, 1.0
    if ms(lo) <= 1.0:
        return 0.0
    while ms(hi) > 1.0:
        hi *= 2.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ms(mid) > 1.0 else (lo, mid)
    return 0.5 * (lo + hi)


class Library:
    """Library tables and the widths that turn them into a prior and a ranking.

    Parameters
    ----------
    effusivity, k, rho_c : array_like
        Per material: e (W s^0.5/(m^2 K)), k (W/(m K)), ρc (J/(m^3 K)).
    names, classes : sequence of str
        Per material: its name and class.
    kernel_floor_ln : float
        Least width in ln e of the prior's kernel (keeps it smooth when u(e) is tiny).
    rho_c_intrinsic_ln : float
        Spread of ln ρc among materials of equal e, added to the prior's variance.
    material_spread_ln : float
        Specimen-to-specimen spread of ln e assumed when naming a material.
    """

    def __init__(self, effusivity, k, rho_c, names, classes, *, kernel_floor_ln: float,
                 rho_c_intrinsic_ln: float, material_spread_ln: float) -> None:
        self.effusivity = np.asarray(effusivity, float)
        self.k = np.asarray(k, float)
        self.rho_c = np.asarray(rho_c, float)
        self.names = [str(s) for s in names]
        self.classes = [str(s) for s in classes]
        if not (self.effusivity.shape == self.k.shape == self.rho_c.shape == (len(self.names),)
                and len(self.classes) == len(self.names) and self.names):
            raise ValueError("library tables must be non-empty and of one length")
        self.kernel_floor_ln = float(kernel_floor_ln)
        self.rho_c_intrinsic_ln = float(rho_c_intrinsic_ln)
        self.material_spread_ln = float(material_spread_ln)
        # The prior's kernel works in ln e and ln rho c: taken once, not per touch.
        self._ln_e, self._ln_rc = np.log(self.effusivity), np.log(self.rho_c)

    @classmethod
    def from_arrays(cls, a: Mapping[str, np.ndarray], *, kernel_floor_ln: float, rho_c_intrinsic_ln: float,
                    material_spread_ln: float) -> "Library":
        """The library of a bundle's arrays (``lib_effusivity``, ``lib_k``, ``lib_rho_c``, ``lib_names``,
        ``lib_class``)."""
        if "lib_effusivity" not in a:
            raise ValueError("bundle has no material library tables (lib_*): cannot name materials")
        return cls(a["lib_effusivity"], a["lib_k"], a["lib_rho_c"], a["lib_names"], a["lib_class"],
                   kernel_floor_ln=kernel_floor_ln, rho_c_intrinsic_ln=rho_c_intrinsic_ln,
                   material_spread_ln=material_spread_ln)

    def prior_rho_c(self, e: float, u_ln_e: float) -> tuple[float, float, bool]:
        """ln(ρc) mean and standard deviation given e; and whether e is outside the library."""
        width = math.hypot(u_ln_e, self.kernel_floor_ln)
        m, v = _kernel_moments(np.array([math.log(e)]), self._ln_e, self._ln_rc, width)
        mean = float(m[0])
        var = float(v[0]) + self.rho_c_intrinsic_ln ** 2
        outside = bool(e < self.effusivity.min() / OUTSIDE_FACTOR or e > self.effusivity.max() * OUTSIDE_FACTOR)
        return mean, math.sqrt(var), outside

    def k_alpha_given_e(self, e: float, u_ln_e: float) -> tuple[float, float, float, float, bool]:
        """k and α of an object of effusivity e, from the library's ρc given e: the one prior.

        ``k = e^2 / ρc`` and ``α = e^2 / (ρc)^2`` with ln ρc and its spread from
        :meth:`prior_rho_c`; every path that has e but not k and α separately (the
        default method on a thick body, the small heater's fit that did not resolve
        them, the calibrated sensor chain) takes them from here.

        Returns
        -------
        k_W_mK, u_ln_k, alpha_m2_s, u_ln_alpha : float
            The values and the standard uncertainties of their logarithms.
        outside : bool
            Whether e lies outside the library (``outside_training_range``).
        """
        ln_rc, u_ln_rc, outside = self.prior_rho_c(e, u_ln_e)
        rc = math.exp(ln_rc)
        k = e * e / rc
        return k, math.hypot(2 * u_ln_e, u_ln_rc), k / rc, math.hypot(2 * u_ln_e, 2 * u_ln_rc), outside

    def identify(self, e: float, u_ln_e: float, top: int = 3) -> list[tuple[str, float]]:
        """Library materials ranked by likelihood of the measured e, with probabilities."""
        s = math.hypot(u_ln_e, self.material_spread_ln)
        z = (math.log(e) - self._ln_e) / s
        ll = -0.5 * z ** 2
        p = np.exp(ll - ll.max())
        p /= p.sum()
        order = np.argsort(-p)[:top]
        return [(self.names[i], float(p[i])) for i in order]
