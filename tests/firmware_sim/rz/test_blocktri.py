"""The block-tridiagonal factor's scaled sweeps and its split inverse, against dense linear algebra."""

import numpy as np
import pytest

from firmware_sim.rz import blocktri as B
from tests.firmware_sim.rz.test_solver import _dense, _system


def test_a_zero_coupling_among_coupled_unknowns_is_solved_like_any_other():
    """The sweeps carry each row scaled by its coupling to the next; where one is exactly zero
    (while its neighbours couple) the row keeps a unit scale and masks that coupling."""
    rng = np.random.default_rng(7)
    diag, off_in, off_between = _system(rng, n=6, m=8)
    off_between[1, 2] = 0.0
    off_between[3, [0, 5]] = 0.0
    fac = B.BlockTridiagonal(diag, off_in, off_between)
    assert any(e[5] is not None for e in fac._fwd)     # the masked path is the one exercised
    rhs = rng.normal(size=diag.shape)
    ref = np.linalg.solve(_dense(diag, off_in, off_between), rhs.reshape(-1)).reshape(diag.shape)
    np.testing.assert_allclose(fac.solve(rhs), ref, rtol=1e-12, atol=1e-13)


@pytest.mark.parametrize("short_rows", [(), (1, 3)])
def test_blocks_wider_than_the_split_width_solve_as_the_dense_system(short_rows):
    m = 2 * B._SPLIT_WIDTH + 3
    rng = np.random.default_rng(11)
    diag, off_in, off_between = _system(rng, n=4, m=m, short_rows=short_rows)
    rhs = rng.normal(size=diag.shape)
    ref = np.linalg.solve(_dense(diag, off_in, off_between), rhs.reshape(-1)).reshape(diag.shape)
    np.testing.assert_allclose(B.BlockTridiagonal(diag, off_in, off_between).solve(rhs), ref, rtol=1e-12, atol=1e-13)


@pytest.mark.parametrize("n", [B._SPLIT_WIDTH, B._SPLIT_WIDTH + 1, 75, 95])
def test_the_split_inverse_is_the_inverse_to_round_off(n):
    rng = np.random.default_rng(n)
    A = rng.normal(size=(n, n)) / np.sqrt(n)
    S = A @ A.T + np.eye(n)
    G = B._inverse(S)
    assert np.max(np.abs(G @ S - np.eye(n))) < 1e-13
    np.testing.assert_allclose(G, np.linalg.inv(S), rtol=0, atol=1e-13 * np.max(np.abs(G)))


def test_a_narrow_block_is_inverted_by_np_linalg_inv_bit_for_bit_and_a_singular_one_raises():
    """_inverse calls the gufunc behind np.linalg.inv directly (its wrapper costs ~10 % of a 47-wide
    inverse): the same LAPACK call, so the same bits, and the same error on a singular block."""
    rng = np.random.default_rng(13)
    A = rng.normal(size=(B._SPLIT_WIDTH, B._SPLIT_WIDTH))
    S = A @ A.T + np.eye(B._SPLIT_WIDTH)
    assert np.array_equal(B._inverse(S), np.linalg.inv(S))
    for n in (3, 2 * B._SPLIT_WIDTH):
        with pytest.raises(np.linalg.LinAlgError):
            B._inverse(np.ones((n, n)))


def test_only_the_rows_a_factor_may_share_are_kept_and_a_shared_row_solves_bit_for_bit():
    """``shared_rows`` spends the row cache on the leading rows other matrices have (a probe's, above
    its object): those are kept and taken, the rest eliminated afresh; the factor is the same."""
    from tests.firmware_sim.rz.test_solver import _eliminated_afresh

    rng = np.random.default_rng(17)
    base = _system(rng, n=10, m=8, short_rows=(0, 1, 2))
    other_object = [a.copy() for a in base]
    other_object[0][6:] += 0.25                       # rows 6-9 differ
    other_probe = [a.copy() for a in base]
    other_probe[0][2, 1] += 0.125                     # row 2 differs: it and every later row miss
    rhs = rng.normal(size=(10, 8))
    saved = dict(B._ROW_CACHE)
    B.clear_row_cache()
    try:
        B.BlockTridiagonal(*base, shared_rows=4)
        assert len(B._ROW_CACHE) == 4
        shared = B.BlockTridiagonal(*other_object, shared_rows=4)
        assert len(B._ROW_CACHE) == 4                 # its four leading rows were taken, none added
        B.BlockTridiagonal(*other_probe, shared_rows=4)
        assert len(B._ROW_CACHE) == 6                 # rows 2 and 3 are another probe's
        B.BlockTridiagonal(*base, shared_rows=0)
        assert len(B._ROW_CACHE) == 6
    finally:
        B.clear_row_cache()
        for k, v in saved.items():
            B._keep_row(k, v)
    fresh = _eliminated_afresh(other_object)
    assert np.array_equal(shared.solve(rhs), fresh.solve(rhs))


def test_a_world_shares_its_probes_rows_above_the_object_only():
    from firmware_sim.clock import VirtualClock
    from firmware_sim.rz.probe_world import FaithfulWorld
    from firmware_sim.rz.solver import _Operator
    from firmware_sim.scene.files import read_scene

    w = FaithfulWorld.for_scene(read_scene("glass_15V_faithful"), VirtualClock(), dt_s=0.02)
    contact = _Operator(w._grid(w._key(w.phases()[1])).grid)
    air = _Operator(w._grid(("air",)).grid)
    assert not contact.transpose and contact.shared_rows == w._grid(w._key(w.phases()[1])).n_probe_rows
    assert air.transpose and air.shared_rows is None  # no object: every row, as any other grid
