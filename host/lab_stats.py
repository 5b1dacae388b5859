"""Statistics of N touches of one sample: mean, spread, RSD, and whether the spread agrees with the stated u.

A lab reports repeated readings as mean ± RSD (C-Therm's TCi: RSD 1-2 % over
≥ 10 readings).  Each ThermoTouch answer also states its own standard
uncertainty u (k = 1), so a series can check it: if the touches scatter only
by what their u's describe, the chi-square of the values about their
u-weighted mean,

    chi2 = sum(((x_i - x_w) / u_i) ** 2),   dof = n - 1,

follows the chi-square distribution with n - 1 degrees of freedom.  The
verdict is two-sided at :data:`TAIL` per side (95 % together):

* ``agrees``: neither tail is below TAIL;
* ``spread_exceeds_u``: P(chi2 >= observed) < TAIL -- the touches differ by
  more than their u's say (u understated, or the sample/contact changed);
* ``spread_below_u``: P(chi2 <= observed) < TAIL -- the touches agree better
  than their u's say: u holds parts every touch shares (calibration, model,
  the library prior), which a repeat cannot show;
* ``too_few``: fewer than :data:`MIN_FOR_VERDICT` answers, or a touch
  without u.

The same band as a ratio: ``sd / rms(u)`` is accepted within
``sqrt(chi2_{dof}(TAIL) / dof) .. sqrt(chi2_{dof}(1 - TAIL) / dof)``
(:func:`ratio_band`), which the report prints beside the ratio.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

__all__ = ["TAIL", "MIN_FOR_VERDICT", "VERDICTS", "QUANTITIES", "summarize", "ratio_band", "verdict_text"]

#: Probability in each tail of the chi-square test below which the spread disagrees with u.
TAIL = 0.025
#: Fewest answered touches for a verdict (two touches give one degree of freedom: no test worth stating).
MIN_FOR_VERDICT = 3

#: What each verdict means, in the words of the report.
VERDICTS = {
    "agrees": "the spread agrees with the stated u",
    "spread_exceeds_u": "the touches scatter more than their stated u says (u understated, or the sample or "
                        "the contact changed between touches)",
    "spread_below_u": "the touches scatter less than their stated u says (u holds parts every touch shares: "
                      "calibration, model, library prior)",
    "too_few": "too few touches with a stated u for a verdict",
}

#: Quantities of an answer a series summarises: (key, its u's key, label, unit, display scale).
QUANTITIES = (
    ("effusivity_W_s05_m2K", "effusivity_W_s05_m2K_u", "effusivity e", "W s^0.5/(m^2 K)", 1.0),
    ("k_W_mK", "k_W_mK_u", "conductivity k", "W/(m K)", 1.0),
    ("alpha_m2_s", "alpha_m2_s_u", "diffusivity alpha", "mm^2/s", 1e6),
)


# The chi-square distribution's functions come from scipy.special, not scipy.stats: importing
# scipy.stats costs ~1 s of CPU (every distribution's docstring is built), scipy.special a quarter of
# that, and scipy.stats's chi2 is these very functions behind argument checks (its _sf is chdtrc,
# _cdf chdtr, _ppf 2 gammaincinv(df/2, p)): the same numbers to the bit, for c2 >= 0, inf and nan too.
def _chi2_sf(c2: float, dof: int) -> float:
    """P(chi2_dof >= c2) (upper tail), as ``scipy.stats.chi2.sf``."""
    from scipy.special import chdtrc  # noqa: PLC0415 - host side only

    return float(chdtrc(dof, c2))


def _chi2_cdf(c2: float, dof: int) -> float:
    """P(chi2_dof <= c2) (lower tail), as ``scipy.stats.chi2.cdf``."""
    from scipy.special import chdtr  # noqa: PLC0415 - host side only

    return float(chdtr(dof, c2))


def _chi2_ppf(p: float, dof: int) -> float:
    """The chi-square quantile at probability ``p`` (0 < p < 1), as ``scipy.stats.chi2.ppf``."""
    from scipy.special import gammaincinv  # noqa: PLC0415 - host side only

    return float(2 * gammaincinv(dof / 2, p))


def ratio_band(dof: int, tail: float = TAIL) -> tuple[float, float]:
    """The accepted range of ``sd / rms(u)`` for ``dof`` degrees of freedom (equal u's)."""
    return math.sqrt(_chi2_ppf(tail, dof) / dof), math.sqrt(_chi2_ppf(1.0 - tail, dof) / dof)


def summarize(values: Sequence[float], us: Sequence[float | None]) -> dict:
    """Mean, sample standard deviation, RSD and the agreement of the spread with the stated u's.

    Parameters
    ----------
    values : sequence of float
        The answered touches' values (finite).
    us : sequence of float or None
        Their stated standard uncertainties (k = 1); None or <= 0 where a
        touch stated none (then no chi-square).

    Returns
    -------
    dict
        ``n, mean, sd, rsd, sem, min, max, u_mean, u_rms, weighted_mean,
        chi2, dof, chi2_dof, p_value (upper tail), p_lower, sd_over_u_rms,
        ratio_band, verdict`` -- None where the series cannot give it (sd
        needs two values).
    """
    x = np.asarray(list(values), dtype=np.float64)
    n = int(x.size)
    out: dict = {"n": n, "mean": None, "sd": None, "rsd": None, "sem": None, "min": None, "max": None,
                 "u_mean": None, "u_rms": None, "weighted_mean": None, "chi2": None, "dof": None,
                 "chi2_dof": None, "p_value": None, "p_lower": None, "sd_over_u_rms": None, "ratio_band": None,
                 "verdict": "too_few"}
    if n == 0:
        return out
    if len(us) != n:
        raise ValueError(f"{n} values but {len(us)} uncertainties")
    mean = float(np.mean(x))
    out.update(mean=mean, min=float(x.min()), max=float(x.max()))
    if n >= 2:
        sd = float(np.std(x, ddof=1))
        out.update(sd=sd, rsd=sd / abs(mean) if mean != 0 else None, sem=sd / math.sqrt(n))
    have_u = all(u is not None and math.isfinite(u) and u > 0 for u in us)
    if not have_u:
        return out
    u = np.asarray(list(us), dtype=np.float64)
    out.update(u_mean=float(np.mean(u)), u_rms=float(np.sqrt(np.mean(u ** 2))))
    w = 1.0 / u ** 2
    xw = float(np.sum(w * x) / np.sum(w))
    out["weighted_mean"] = xw
    if n < 2:
        return out
    c2 = float(np.sum(((x - xw) / u) ** 2))
    dof = n - 1
    p_upper, p_lower = _chi2_sf(c2, dof), _chi2_cdf(c2, dof)
    out.update(chi2=c2, dof=dof, chi2_dof=c2 / dof, p_value=p_upper, p_lower=p_lower,
               sd_over_u_rms=out["sd"] / out["u_rms"], ratio_band=list(ratio_band(dof)))
    if n >= MIN_FOR_VERDICT:
        out["verdict"] = ("spread_exceeds_u" if p_upper < TAIL else "spread_below_u" if p_lower < TAIL
                          else "agrees")
    return out


def verdict_text(s: dict) -> str:
    """One line: the chi-square, its p-value, the ratio with its band, and the verdict in words."""
    if s.get("chi2") is None:
        return VERDICTS["too_few"]
    lo, hi = s["ratio_band"]
    return (f"chi2/dof {s['chi2_dof']:.2f} (dof {s['dof']}, p {s['p_value']:.3f}); sd/rms(u) "
            f"{s['sd_over_u_rms']:.2f} (accepted {lo:.2f}..{hi:.2f}): {VERDICTS[s['verdict']]}")
