"""The open-set answer for many touches at once: :class:`Recognition` and :func:`classify_rows`.

:meth:`edge.recognition.object_set.ObjectSet.classify` is :func:`classify_rows` of one touch and
:meth:`~edge.recognition.object_set.ObjectSet.classify_many` of many: one definition, so a batch's
every number is the per-touch one to the bit (tests/edge/recognition/test_classify_many.py).  That
holds because every step is element-wise on a C-contiguous ``(touches, objects)`` array or a
reduction along its last (contiguous) axis, which NumPy sums row by row in the order it sums one
touch's 1-D row; the scalar steps a touch had on Python floats (``math.log`` of e, α and the
background's α term; ``z_of_p``'s scalar bisection) stay per touch on Python floats.  ISSUE #33:
called touch by touch from the host's fits, ~40 small NumPy calls per touch were ~1.5 CPU-s of the
test suite.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from edge.recognition.objects import UNKNOWN, UNKNOWN_LN_E_SPAN
from edge.recognition.stats import p_crit_of, tail_p, z_of_p
from edge.recognition.touch import BROAD_LN, effective_u_ln_alpha

__all__ = ["Recognition", "check_touch", "classify_rows"]

_LN_SQRT_2PI = 0.5 * math.log(2 * math.pi)


@dataclass
class Recognition:
    """What a touch was: the object (or ``"unknown"``), its class, and the posteriors."""

    object: str
    object_posterior: float
    cls: str
    class_posterior: float
    candidates: list[tuple[str, float]]
    unknown_posterior: float
    class_posteriors: dict[str, float] = field(default_factory=dict)
    #: Standardised distance (1-degree-of-freedom equivalent) to the best-fitting object.
    z_min: float = 0.0
    #: The best-fitting object by the open-set test (even when the answer is "unknown").
    nearest: str = ""

    @property
    def accepted(self) -> bool:
        """True when the touch was recognised as one of the set's objects."""
        return self.object != UNKNOWN

    def to_dict(self) -> dict:
        """JSON-able dict (``class`` rather than ``cls``)."""
        return {
            "object": self.object,
            "object_posterior": float(self.object_posterior),
            "class": self.cls,
            "class_posterior": float(self.class_posterior),
            "candidates": [[n, float(p)] for n, p in self.candidates],
            "unknown_posterior": float(self.unknown_posterior),
            "class_posteriors": {c: float(p) for c, p in self.class_posteriors.items()},
            "z_min": float(self.z_min),
            "nearest": self.nearest,
        }


def check_touch(e: float, u_ln_e: float, alpha: float | None, u_ln_alpha: float | None, corr: float) -> None:
    """Raise ValueError for a touch :meth:`~edge.recognition.object_set.ObjectSet.classify` cannot answer."""
    if not (e > 0 and math.isfinite(e)):
        raise ValueError(f"e must be a positive finite number, got {e!r}")
    if not (u_ln_e >= 0 and math.isfinite(u_ln_e)):
        raise ValueError(f"u_ln_e must be a non-negative finite number, got {u_ln_e!r}")
    if alpha is not None:
        if not (alpha > 0 and math.isfinite(alpha) and u_ln_alpha is not None and u_ln_alpha > 0
                and math.isfinite(u_ln_alpha)):
            raise ValueError(f"alpha must be positive with a positive uncertainty, got {alpha!r} +- {u_ln_alpha!r}")
        if not (math.isfinite(corr) and abs(corr) < 1.0):
            raise ValueError(f"corr must lie in (-1, 1), got {corr!r}")


def classify_rows(s, e: Sequence[float], u_ln_e: Sequence[float], alpha: Sequence[float | None],
                  u_ln_alpha: Sequence[float | None], corr: Sequence[float], top: int = 3,
                  stated: Sequence[bool] | None = None) -> list[Recognition]:
    """The :class:`Recognition` of each touch (checked by :func:`check_touch`) by the object set ``s``.

    Parameters
    ----------
    s : ObjectSet
        The set (its arrays ``ln_e``, ``spread``..., its calibration scalars and :meth:`log_terms`).
    e, u_ln_e : sequence of float
        Each touch's effusivity and the relative standard uncertainty of it.
    alpha, u_ln_alpha, corr : sequence
        Each touch's measured α (None: not measured), its u(ln α) and the ln e / ln α error correlation.
    top : int
        Number of candidates listed.
    stated : sequence of bool, optional
        Per touch, False where ``u_ln_e`` is a width the rule fixed (``poor_fit_ln``, or a ``BROAD_LN``
        widening): used as it is, not shrunk (:meth:`ObjectSet.likelihood_u`); default every u a stated one.

    Returns
    -------
    list of Recognition
        One per touch, in order.
    """
    n_t = len(e)
    has_a = [a is not None for a in alpha]
    # math.log per touch, as one touch always had it: NumPy's vector log may differ in the last bit.
    ln_e = np.array([math.log(x) for x in e], float)
    u = np.array(u_ln_e, float)
    kw = {}
    if any(has_a):   # NaN marks a touch without α: log_terms gives its row the e-only terms
        kw = dict(ln_alpha=np.array([math.log(a) if h else math.nan for a, h in zip(alpha, has_a)]),
                  u_ln_alpha=np.array([ua if h else math.nan for ua, h in zip(u_ln_alpha, has_a)], float),
                  corr=np.array([c if h else 0.0 for c, h in zip(corr, has_a)], float))
    if stated is not None and not all(stated):
        kw["stated"] = np.array(stated, bool)
    q, hld, dof = s.log_terms(ln_e, u, **kw)
    t = s.temperature
    d2 = q / t
    # Open-set test: the p-value of each object's distance (1 property: |z| > z_crit).
    pvals = tail_p(d2, dof)
    near = np.argmax(pvals, axis=-1)
    pn = pvals.max(axis=-1)   # pvals at near (the maximum is one of the row's values)
    accepted = pn >= p_crit_of(s.z_crit)
    # Mixture: objects (Gaussians, prior (1 - prior_unknown) / n each) and the flat background.
    norm = (1 + np.array(has_a, int))[:, None] * (_LN_SQRT_2PI + 0.5 * math.log(t))
    ln_prior = math.log((1.0 - s.prior_unknown) / len(s))
    lw_obj = ln_prior - 0.5 * d2 - hld - norm
    if s.outlier_weight > 0:   # the core and a broad component with the same centre and prior
        q_o, hld_o, _ = s.outlier_terms(ln_e, u, **kw)
        const = ln_prior - norm
        lw_obj = s.mixture_log_weight(const - 0.5 * d2 - hld, const - 0.5 * q_o / t - hld_o, s.outlier_weight)
    lw_unk0 = math.log(s.prior_unknown) - math.log(UNKNOWN_LN_E_SPAN)
    lw_unk = []
    for h, ua_stated in zip(has_a, u_ln_alpha):
        lw_u = lw_unk0
        if h:
            ua = float(effective_u_ln_alpha(ua_stated, s.alpha_u_growth))
            lw_u -= _LN_SQRT_2PI + 0.5 * math.log(ua ** 2 + BROAD_LN ** 2)
        lw_unk.append(lw_u)
    lw = np.concatenate([lw_obj, np.array(lw_unk)[:, None]], axis=1)
    w = np.exp(lw - lw.max(axis=-1, keepdims=True))
    post = w / w.sum(axis=-1, keepdims=True)
    p_unknown = post[:, -1]
    # With unknown_min_odds r > 0, "unknown" only when the background also holds at least r times the
    # best object's posterior (r = 1: it is the most probable hypothesis).  ISSUE #37: with the test
    # alone, at 2 s 30 in-set touches from the 5 % spread's tail (z 2.4-3.3) were answered "unknown" at
    # 0.16-0.42 -- an answer the device's own posterior called less likely than an object, wrong every
    # time -- and made the < 0.5 reliability bin read 39 % said, 29 % right.
    if s.unknown_min_odds > 0:
        accepted = accepted | (p_unknown < s.unknown_min_odds * post[:, :-1].max(axis=-1))
    # The objects' posteriors printed are the closed-set ones (given the touched object is one of the
    # set's): what the set's calibration fits (host.recognition minimises the true object's NLL over
    # :meth:`posteriors`) and what its reliability is judged on.  The flat background's share is printed
    # beside them (``unknown_posterior``) and the open-set test decides "unknown"; folding the background
    # into every object's posterior made in-set answers read 2-5 points short (issue #37's bench).
    w_obj = np.exp(lw_obj - lw_obj.max(axis=-1, keepdims=True))   # its own maximum: a far touch keeps them finite
    p_obj = w_obj / w_obj.sum(axis=-1, keepdims=True)
    # One bincount over the flat rows (bin: touch x class): each bin adds its touch's weights in the objects'
    # order from 0, as a touch's own bincount does.
    n_cls = len(s.class_names)
    bins = (s._class_index + n_cls * np.arange(n_t)[:, None]).ravel()
    class_post = np.bincount(bins, weights=p_obj.ravel(), minlength=n_t * n_cls).reshape(n_t, n_cls)
    order = np.argsort(-p_obj, axis=-1, kind="stable")[:, :top].tolist()
    best_class = np.argmax(class_post, axis=-1).tolist()
    names, class_names = s.names, s.class_names
    out = []
    for k, (p_row, c_row, ok, pu, j) in enumerate(zip(p_obj.tolist(), class_post.tolist(), accepted.tolist(),
                                                     p_unknown.tolist(), near.tolist())):
        candidates = [(names[i], p_row[i]) for i in order[k]]
        if ok:
            ci = best_class[k]
            obj, obj_p, cls, cls_p = names[order[k][0]], p_row[order[k][0]], class_names[ci], c_row[ci]
        else:
            obj, obj_p, cls, cls_p = UNKNOWN, pu, UNKNOWN, pu
        p_near = float(pn[k])
        z_min = math.sqrt(d2[k, j]) if dof[k, j] == 1 else (float(z_of_p(p_near)) if p_near > 0 else math.inf)
        out.append(Recognition(obj, obj_p, cls, cls_p, candidates, pu, dict(zip(class_names, c_row)), z_min,
                               names[j]))
    return out
