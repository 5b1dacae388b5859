"""The library prior and material naming (edge.estimation.identification)."""

import math

import numpy as np
import pytest

from edge.estimation.identification import Library


def _lib(**kw):
    args = dict(kernel_floor_ln=0.06, rho_c_intrinsic_ln=0.10, material_spread_ln=0.05)
    args.update(kw)
    e = np.array([500.0, 1500.0, 20000.0])
    rc = np.array([1.7e6, 2.0e6, 2.4e6])
    k = e ** 2 / rc
    return Library(e, k, rc, ["pmma", "glass", "aluminium"], ["polymer", "glass", "metal"], **args)


def test_identify_ranks_the_nearest_effusivity_first_and_normalises():
    lib = _lib()
    ranked = lib.identify(1480.0, 0.02)
    assert ranked[0][0] == "glass"
    assert sum(p for _, p in ranked) == pytest.approx(1.0)
    assert ranked[0][1] > 0.99


def test_identify_is_less_sure_when_the_measurement_is_uncertain():
    lib = _lib()
    sharp = dict(lib.identify(900.0, 0.02))
    broad = dict(lib.identify(900.0, 1.0))
    assert max(broad.values()) < max(sharp.values())


def test_prior_follows_the_neighbours_and_flags_extrapolation():
    lib = _lib()
    mean, sd, outside = lib.prior_rho_c(1500.0, 0.01)
    assert mean == pytest.approx(math.log(2.0e6), abs=0.01)
    assert sd >= 0.10 and not outside
    assert lib.prior_rho_c(100.0, 0.01)[2] and lib.prior_rho_c(1e5, 0.01)[2]


def test_tables_of_different_lengths_are_refused():
    with pytest.raises(ValueError, match="one length"):
        Library([1.0, 2.0], [1.0], [1.0, 2.0], ["a", "b"], ["x", "y"], kernel_floor_ln=0.1,
                rho_c_intrinsic_ln=0.1, material_spread_ln=0.1)


def test_from_arrays_needs_the_library_tables():
    with pytest.raises(ValueError, match="lib_"):
        Library.from_arrays({}, kernel_floor_ln=0.1, rho_c_intrinsic_ln=0.1, material_spread_ln=0.1)
