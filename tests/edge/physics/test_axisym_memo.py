"""The axisymmetric model's transforms, computed once per model parts and arguments."""

import numpy as np

from edge.physics import axisym
from edge.physics.axisym import AxisymModel
from edge.physics.geometry import SMALL_HEATER
from edge.physics.solids import Solid


def test_a_repeated_transform_is_the_first_bit_for_bit_and_the_caller_owns_its_copy():
    m = AxisymModel(SMALL_HEATER, np.arange(1, 41) / 20.0)
    axisym._TRANSFORMS.clear()
    first = m.transforms(1.1, 5e-7, derivatives=True)
    want = [a.copy() for a in first]
    for a in first:
        a[...] = np.nan                                   # the caller may write into its arrays
    again = m.head(10).transforms(1.1, 5e-7, derivatives=True)   # another model on the same parts
    assert len(axisym._TRANSFORMS) == 1
    assert all(np.array_equal(a, b) for a, b in zip(again, want))
    axisym._TRANSFORMS.clear()
    assert all(np.array_equal(a, b) for a, b in zip(m.transforms(1.1, 5e-7, derivatives=True), want))


def test_other_arguments_or_another_substrate_are_computed_not_recalled():
    m = AxisymModel(SMALL_HEATER, np.arange(1, 41) / 20.0)
    axisym._TRANSFORMS.clear()
    base = m.transforms(1.1, 5e-7)[0]
    foam = Solid(k_W_mK=0.05, rho_kg_m3=40.0, c_J_kgK=1400.0)
    for T in (m.transforms(1.1, 5e-7, contact_resistance_m2K_W=1e-4)[0], m.transforms(1.1, 5e-7, thickness_m=2e-3,
                                                                                        back="insulated")[0],
              m.with_substrate(foam).transforms(1.1, 5e-7)[0], m.transforms(1.2, 5e-7)[0]):
        assert not np.array_equal(T, base)
    assert np.array_equal(m.transforms(np.float64(1.1), 5e-7)[0], base)
    assert len(axisym._TRANSFORMS) == 5
