"""The scale on the stated u alone, ``u_var_scale`` (ISSUE #37): the spread stays, files written before load."""

import math

import numpy as np
import pytest

from edge.recognition import KnownObject, ObjectSet, ObjectSetError

OBJS = tuple(KnownObject.from_properties(n, "polymer", k, 1200, 1400, 0.05) for n, k in (("a", 0.2), ("b", 0.22)))


def test_the_scale_acts_on_the_stated_u_alone_and_not_on_the_spread():
    s, k = ObjectSet(OBJS), 0.25
    sk = s.with_calibration(u_var_scale=k)
    x, u = np.log([300.0, 350.0]), np.array([0.04, 0.08])
    q, h, _ = sk.log_terms(x, u)
    q1, h1, _ = s.log_terms(x, u * math.sqrt(k))
    assert np.allclose(q, q1) and np.allclose(h, h1)
    # The temperature scales the spread with u; the scale leaves a touch with no stated u at the spread.
    q0, _, _ = sk.log_terms(x, np.zeros(2))
    assert np.allclose(q0, (x[:, None] - s.ln_e) ** 2 / 0.05 ** 2)
    # With a measured alpha, the ln e - ln alpha covariance follows the scaled u(ln e).
    a = np.log([OBJS[0].alpha_m2_s * 1.1] * 2)
    kw = dict(ln_alpha=a, u_ln_alpha=np.array([0.1, 0.2]), corr=np.array([0.5, -0.3]))
    assert np.allclose(sk.log_terms(x, u, **kw)[0], s.log_terms(x, u * math.sqrt(k), **kw)[0])


def test_a_set_without_the_scale_writes_what_it_did_and_one_with_it_round_trips():
    s = ObjectSet(OBJS, temperature=0.8)
    assert "u_var_scale" not in s.to_csv_text()       # files written before this field: unchanged, and they load
    assert ObjectSet.from_csv_text(s.to_csv_text()).u_var_scale == 1.0
    t = ObjectSet(OBJS, u_var_scale=0.3, contact_calibration={1.0: {"temperature": 1.0, "u_var_scale": 0.2},
                                                              2.0: {"u_var_scale": 0.05}})
    text = t.to_csv_text()
    assert "#@ u_var_scale = 0.3" in text and "#@ u_var_scale@1s = 0.2" in text
    back = ObjectSet.from_csv_text(text)
    assert back.u_var_scale == 0.3 and back.at_contact(0.9).u_var_scale == 0.2 and back.at_contact(3.0).u_var_scale == 0.05
    e = OBJS[0].e_W_s05_m2K
    est = {"effusivity_W_s05_m2K": e * 1.05, "effusivity_W_s05_m2K_u": 0.1 * e}
    # A smaller scale on a large stated u: a sharper answer between the two close objects.
    assert back.classify_estimate(est, contact_time_s=2.0).object_posterior > \
        back.classify_estimate(est, contact_time_s=1.0).object_posterior
    base = "name,class,k_W_mK,rho_kg_m3,c_J_kgK\na,polymer,0.2,1200,1400\n"
    for bad in ("#@ u_var_scale = 0", "#@ u_var_scale@1s = -1"):
        with pytest.raises(ObjectSetError):
            ObjectSet.from_csv_text(bad + "\n" + base)
