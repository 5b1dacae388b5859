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
