"""ObjectSet.classify_many is classify touch by touch, bit for bit (ISSUE #33: the host's fits classify in batches)."""

import math

import numpy as np
import pytest

from edge.recognition import UNKNOWN, KnownObject, ObjectSet

LIBRARY = ObjectSet.from_library()
#: Objects given by e alone beside the library's objects with k, ρ, c: a measured α meets both kinds.
MIXED = ObjectSet([KnownObject(n, c, e) for n, c, e in (("pine", "wood", 322.5), ("rubber", "rubber", 360.7),
                                                          ("mdf", "wood", 377.9))]
                  + [o for o in LIBRARY.objects[::5]], z_crit=2.45)
SHRINK = dict(u_shrink=0.6, u_typ_ln0=-3.5, u_typ_ln1=0.1, u_typ_ln2=0.01, u_var_scale=1.3)


def _sets():
    """Every calibration branch of classify: T != 1, outlier component, unknown_min_odds, shrink, bias, all at once."""
    lib = LIBRARY.with_calibration(temperature=1.0)
    yield "library", LIBRARY
    yield "3 objects", ObjectSet(MIXED.objects[:3])            # fewer than 8 terms: NumPy's plain sum
    yield "mixed", MIXED                                       # 9-33 terms: NumPy's 8-way unrolled sum
    yield "tempered", lib.with_calibration(temperature=1.7, z_crit=2.3)
    yield "outlier", MIXED.with_calibration(outlier_weight=0.05, outlier_ln=0.4)
    yield "min odds", MIXED.with_calibration(unknown_min_odds=1.0, temperature=0.8)
    yield "shrink", MIXED.with_calibration(**SHRINK)
    yield "all", MIXED.with_calibration(**SHRINK, outlier_weight=0.1, outlier_ln=0.5, unknown_min_odds=2.0,
                                        temperature=1.4, bias_ln=0.03, alpha_u_growth=3.0)


def _touches(s, rng, n):
    """Touches near the objects, between them and far from all (unknown), half with a measured α."""
    ln_e = rng.choice(s.ln_e, n) + rng.normal(0.0, 0.1, n) + rng.choice([0.0, 0.0, 0.0, 2.0, -3.0], n)
    alpha = np.where(rng.random(n) < 0.5, np.exp(rng.normal(-14.5, 1.5, n)), np.nan)
    return (np.exp(ln_e), rng.uniform(0.0, 0.3, n), alpha, rng.uniform(0.02, 0.9, n), rng.uniform(-0.9, 0.9, n))


@pytest.mark.parametrize("name, s", list(_sets()), ids=[n for n, _ in _sets()])
def test_a_batch_answers_every_touch_as_classify_does_bit_for_bit(name, s):
    e, u, alpha, ua, corr = _touches(s, np.random.default_rng(len(name)), 24)
    u[0] = 0.0 if (s.spread > 0).all() else 1e-9            # a zero stated u, where the spreads keep a width
    for top, kw in ((3, dict(alpha=alpha, u_ln_alpha=ua, corr=corr)), (len(s) + 2, {})):
        batch = s.classify_many(e, u, top=top, **kw)
        for k, got in enumerate(batch):
            one = ({} if not kw or math.isnan(alpha[k]) else
                   dict(alpha=float(alpha[k]), u_ln_alpha=float(ua[k]), corr=float(corr[k])))
            want = s.classify(float(e[k]), float(u[k]), top=top, **one)
            # == on every float (dataclass equality compares the fields), not approx.
            assert got == want, (name, k)
    answers = {r.object for r in s.classify_many(e, u, alpha=alpha, u_ln_alpha=ua, corr=corr)}
    assert UNKNOWN in answers and len(answers) > 2          # the inputs reach both kinds of answer


def test_numpy_sums_each_row_of_the_objects_axis_as_it_sums_one_touch():
    # What the batch's bit-identity rests on: a reduction along the last, contiguous axis.
    rng = np.random.default_rng(33)
    for n in (1, 2, 7, 8, 9, 17, 27, 33, 128, 129, 300):
        a = np.exp(rng.normal(0.0, 5.0, (50, n)))
        assert a.sum(axis=-1).tolist() == [row.sum() for row in a]
        assert (a / a.sum(axis=-1, keepdims=True)).tolist() == [(row / row.sum()).tolist() for row in a]


def test_scalars_broadcast_an_empty_batch_is_empty_and_a_bad_touch_is_named():
    s = MIXED
    assert s.classify_many([], []) == []
    both = s.classify_many([322.5, 1369.3], 0.02)
    assert both == [s.classify(322.5, 0.02), s.classify(1369.3, 0.02)]
    assert s.classify_many(322.5, 0.02) == [s.classify(322.5, 0.02)]
    # None or NaN in alpha: that touch without α.
    mixed = s.classify_many([322.5, 322.5], 0.02, alpha=[None, 1.2e-7], u_ln_alpha=[None, 0.1], corr=[0.0, 0.3])
    assert mixed == [s.classify(322.5, 0.02), s.classify(322.5, 0.02, alpha=1.2e-7, u_ln_alpha=0.1, corr=0.3)]
    for bad, word in (([322.5, -1.0], "e must be"), ([322.5, math.nan], "e must be")):
        with pytest.raises(ValueError, match=f"touch 1: {word}"):
            s.classify_many(bad, 0.02)
    with pytest.raises(ValueError, match="touch 0: u_ln_e"):
        s.classify_many([322.5], [-0.1])
    with pytest.raises(ValueError, match="touch 1: corr"):
        s.classify_many([322.5, 322.5], 0.02, alpha=1e-7, u_ln_alpha=0.1, corr=[0.0, 1.0])
    with pytest.raises(ValueError, match="1-D"):
        s.classify_many([[322.5]], 0.02)
