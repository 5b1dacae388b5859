"""AxisymModel's transforms, computed in place, are the plain formulas' to the last bit.

``AxisymModel._transforms`` writes its intermediates into its own temporaries (a third of a running
refit's transform cost was fresh arrays).  The oracle here is the formulas written as plain expressions
(as the model computed them before), evaluated on the model's own parts: any change of an operation, of
an operand's order or of a buffer that is still needed shows as a differing bit.  Both probes: the
paper probe's grid is over NumPy's 256 KiB temporary-elision size, where NumPy itself reorders
``x * (temporary)``; the small heater's is under it.
"""

import numpy as np
import pytest

from edge.physics.axisym import AxisymModel, _TRANSFORM_PARTS, series_contact
from edge.physics.geometry import PAPER, SMALL_HEATER

T_S = np.arange(1, 201) / 40.0
# (k, alpha, thickness, back, R_c): a thick insulator, a metal, finite objects on both backs, a contact.
OBJECTS = [(0.19, 1.1e-7, None, "infinite", 0.0), (16.0, 4.0e-6, None, "infinite", 0.0),
           (1.4, 8.0e-7, 3.0e-3, "insulated", 0.0), (0.6, 1.5e-7, 2.0e-3, "fixed", 0.0),
           (0.19, 1.1e-7, None, "infinite", 2.0e-4), (1.4, 8.0e-7, 3.0e-3, "fixed", 5.0e-5)]


def _tanh(z):
    e = np.exp(-2.0 * z)
    return (1.0 - e) / (1.0 + e)


def plain_transforms(m, k, alpha, thickness, back, R):
    """The transforms as plain NumPy expressions on ``m``'s parts (fresh arrays for every intermediate)."""
    p_a, go = m._object_gamma_kept(alpha)
    Y = k * go
    fin = not (back == "infinite" or thickness is None)
    if fin:
        t = _tanh(go * thickness)
        Y = Y / t if back == "fixed" else Y * t
    Yo = series_contact(Y, R)
    kgs = m._kgs
    TsYo = m._Ts * Yo
    dd = m._kgs + TsYo
    Ydn = m._kgs * (m._kgsTs + Yo) / dd
    den = 1.0 + TsYo / kgs
    hd = m._B + m._C * Ydn
    r = m._num / (hd * den)
    kT = r * m._Ss
    kq_base = m._qa + Yo * m._qb
    T = kT @ m._w_T
    q = (r * kq_base) @ m._w_q
    dYdn = m._dYdn_num / (dd * dd)
    dlnr = -(m._C * dYdn / hd + m._Ts_kgs / den)
    dkT = kT * dlnr
    dkq = r * (dlnr * kq_base + m._qb)
    dYo_dY = 1.0 / (1.0 + R * Y) ** 2 if R != 0.0 else 1.0
    dgo = -0.5 * p_a / go
    if not fin:
        dY_dgo = k
    elif back == "fixed":
        dY_dgo = k / t - k * go * thickness * (1.0 - t * t) / (t * t)
    else:
        dY_dgo = k * t + k * go * thickness * (1.0 - t * t)
    dtheta = (Y * dYo_dY, dY_dgo * dgo * dYo_dY, -Yo * Yo)
    dT = np.stack([(dkT * d) @ m._w_T for d in dtheta])
    dq = np.stack([(dkq * d) @ m._w_q for d in dtheta])
    return T, q, dT, dq, hd


def bits(a):
    return np.ascontiguousarray(a).view(np.int64)


@pytest.fixture(scope="module", params=[SMALL_HEATER, PAPER], ids=["small-heater", "paper"])
def model(request):
    return AxisymModel(request.param, T_S)


def test_the_paper_grid_is_over_numpys_elision_size_and_the_small_heaters_under_it(model):
    over = model._kgs.nbytes >= 256 * 1024
    assert over == (model.geometry.name == "paper")


@pytest.mark.parametrize("obj", OBJECTS)
def test_in_place_transforms_are_the_plain_formulas_bit_for_bit(model, obj):
    want = plain_transforms(model, *obj)
    got = model._transforms(*obj, True)
    for w, g in zip(want[:4], got):
        assert np.array_equal(bits(w), bits(g))
    # The heater's denominator kept for heater_transform is this object's, intact after the derivatives.
    assert model._last_hd[0] == obj and np.array_equal(bits(model._last_hd[1]), bits(want[4]))
    T, q = model._transforms(*obj, False)
    assert np.array_equal(bits(T), bits(want[0])) and np.array_equal(bits(q), bits(want[1]))


def test_in_place_transforms_leave_the_models_parts_untouched(model):
    before = {name: np.array(getattr(model, name), copy=True) for name in _TRANSFORM_PARTS}
    for obj in OBJECTS:
        model._transforms(*obj, True)
    for name, a in before.items():
        assert np.array_equal(bits(getattr(model, name)), bits(a)), name


@pytest.mark.parametrize("obj", OBJECTS)
def test_a_cold_heater_transform_is_the_plain_formula_bit_for_bit(model, obj):
    """Without the transforms' kept denominator (another object asked last): the film's mean from scratch."""
    model._transforms(*OBJECTS[(OBJECTS.index(obj) + 1) % len(OBJECTS)], False)   # another object's hd kept
    hd = plain_transforms(model, *obj)[4]
    got = model._heater_transform(*obj)
    want = (model._num / hd) @ model._w_h      # the film's read-out weights, set by the call above
    assert np.array_equal(bits(got), bits(want))
