"""The block-tridiagonal factor and the factors the solvers share."""

import numpy as np
import pytest

from firmware_sim.rz import solver as S
from tests.support.faithful import cold_solver_caches


def _dense(diag, off_in, off_between):
    n, m = diag.shape
    A = np.diag(diag.reshape(-1))
    for j in range(n):
        for i in range(m - 1):
            A[j * m + i, j * m + i + 1] = A[j * m + i + 1, j * m + i] = off_in[j, i]
    for j in range(n - 1):
        for i in range(m):
            A[j * m + i, (j + 1) * m + i] = A[(j + 1) * m + i, j * m + i] = off_between[j, i]
    return A


def _system(rng, n=7, m=6, empty_rows=(), short_rows=()):
    """A diagonally dominant SPD stencil; ``short_rows`` couple only their first half, ``empty_rows`` nothing
    (the grid's inactive cells beyond a layer's radius, which the factor solves on their own)."""
    off_in = -rng.uniform(0.1, 1.0, (n, m - 1))
    off_between = -rng.uniform(0.1, 1.0, (n - 1, m))
    for j in short_rows:
        off_in[j, m // 2 - 1:] = 0.0
        if j < n - 1:
            off_between[j, m // 2:] = 0.0
        if j:
            off_between[j - 1, m // 2:] = 0.0
    for j in empty_rows:
        off_in[j] = 0.0
        if j < n - 1:
            off_between[j] = 0.0
        if j:
            off_between[j - 1] = 0.0
    diag = 4.5 + rng.uniform(0.0, 1.0, (n, m))
    return diag, off_in, off_between


@pytest.fixture
def cold(monkeypatch):
    """Empty factor, row and step caches for a test that clears or fills them; the process's own come back after
    it (a clear of those made the worker's later faithful-world tests factor and step everything again)."""
    cold_solver_caches(monkeypatch)


@pytest.mark.parametrize("empty_rows, short_rows", [((), ()), ((), (1, 2, 5)), ((3,), (0, 6)), ((0, 6), ())])
def test_block_solve_equals_the_dense_solve_with_uncoupled_cells(empty_rows, short_rows):
    rng = np.random.default_rng(3)
    diag, off_in, off_between = _system(rng, empty_rows=empty_rows, short_rows=short_rows)
    rhs = rng.normal(size=diag.shape)
    x = S.BlockTridiagonal(diag, off_in, off_between).solve(rhs)
    ref = np.linalg.solve(_dense(diag, off_in, off_between), rhs.reshape(-1)).reshape(diag.shape)
    np.testing.assert_allclose(x, ref, rtol=1e-12, atol=1e-13)


def test_the_same_matrix_shares_one_factor_and_the_cache_stays_within_its_bytes(cold, monkeypatch):
    rng = np.random.default_rng(4)
    a = _system(rng)
    b = _system(rng)
    S.clear_factor_cache()
    fa = S._factor(*a)
    assert S._factor(*(x.copy() for x in a)) is fa          # equal bytes: the cached factor
    assert S._factor(*b) is not fa
    S.clear_factor_cache()
    assert S._factor(*a) is not fa                           # cleared: factored afresh
    # A budget of two factors: the least recently used goes first, the total never exceeds it.
    monkeypatch.setattr(S, "_FACTOR_CACHE_BYTES", 2 * fa.nbytes)
    S.clear_factor_cache()
    systems = [_system(rng) for _ in range(5)]
    factors = [S._factor(*s) for s in systems]
    assert len(S._FACTOR_CACHE) == 2 and sum(f.nbytes for f in S._FACTOR_CACHE.values()) <= 2 * fa.nbytes
    assert S._factor(*systems[-1]) is factors[-1] and S._factor(*systems[0]) is not factors[0]
    S.clear_factor_cache()


def test_threads_solving_with_one_shared_factor_each_get_their_own_answer():
    """Factors are shared between solvers (and worlds step in different threads): the sweeps' work
    vectors are per thread, so concurrent solves never see each other's intermediate values."""
    import sys
    import threading

    rng = np.random.default_rng(5)
    fac = S.BlockTridiagonal(*_system(rng, n=12, m=9, short_rows=(3, 7)))
    rhss = [rng.normal(size=(12, 9)) for _ in range(4)]
    want = [fac.solve(r) for r in rhss]
    old = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # switch threads between almost every bytecode: interleave the sweeps
    wrong = []
    try:
        def solve_many(k):
            for _ in range(300):
                if not np.array_equal(fac.solve(rhss[k]), want[k]):
                    wrong.append(k)
                    return

        threads = [threading.Thread(target=solve_many, args=(k,)) for k in range(4)]
        for th in threads:
            th.start()
        for th in threads:
            th.join(60)
    finally:
        sys.setswitchinterval(old)
    assert not wrong


@pytest.mark.parametrize("scheme", ["trbdf2", "cn", "be"])
def test_one_step_is_one_step_of_run_bit_for_bit(scheme):
    # The world steps with Solver.step; the solver's own tests march with run. Both must be the
    # same scheme to the last bit, from a field that is not uniform and with ambient forcing.
    from edge.physics.solids import Solid
    from firmware_sim.rz.grid import probe_grid

    s = S.Solver(probe_grid(Solid(1.1, 2500.0, 800.0)), 0.01, scheme, rannacher_steps=0)
    T0 = s.run(s.initial_field(25.0, 22.0), 3, s.heater_source_W(), 2.0, keep_field=True).T_final_K
    rec = s.run(T0, 1, s.heater_source_W(), 5.0, keep_field=True)
    T1, e_in, e_lost = s.step(T0, s.heater_source_W(), 5.0)
    assert np.array_equal(T1, rec.T_final_K)
    assert e_in == rec.E_in_J[-1] and e_lost == rec.E_lost_J[-1]
    assert not np.array_equal(T1, T0) and e_in > 0


def _air_probe(top_K: float = 300.0, side_K: float = 300.0):
    """The probe alone, losing heat from its top, side and face to surroundings at those temperatures."""
    from firmware_sim.rz.grid import Boundary, probe_grid

    return probe_grid(None, top=Boundary(10.0, top_K), side=Boundary(5.0, side_K), bottom=Boundary(10.0, top_K))


@pytest.mark.parametrize("scheme", ["trbdf2", "cn", "be"])
def test_a_field_at_rest_stays_exactly_at_rest_and_books_the_solves_heat(scheme):
    # The probe in air at the temperature of every surface, unheated: the step returns the field
    # itself, where the solve returned it to round-off, and books the same heat.
    s = S.Solver(_air_probe(), 0.01, scheme, rannacher_steps=0)
    rest = s.initial_field(300.0)
    T1, e_in, e_lost = s.step(rest, s.heater_source_W(), 0.0)
    assert np.array_equal(T1, rest) and T1 is not rest and e_in == 0.0
    solved, _, lost = s._advance(rest.copy(), s.g_t, s._loss(rest), False, rest=False)
    assert np.max(np.abs(solved - rest)) <= 1e-12 * 300.0
    assert e_lost == pytest.approx(lost, abs=1e-15)
    rec = s.run(rest, 5, s.heater_source_W(), 0.0, keep_field=True)
    assert np.array_equal(rec.T_final_K, rest) and np.all(rec.T_tc_K == rec.T_tc_K[0])


def test_heat_a_different_field_or_a_second_surface_temperature_are_solved():
    s = S.Solver(_air_probe(), 0.01)
    rest = s.initial_field(300.0)
    # Heated: it warms.
    T1, e_in, _ = s.step(rest, s.heater_source_W(), 1.0)
    assert e_in > 0 and T1.max() > 300.0
    # Another uniform temperature is not at rest: it relaxes towards the surfaces' 300 K.
    T2, _, lost = s.step(s.initial_field(301.0), s.heater_source_W(), 0.0)
    assert T2.min() < 301.0 and lost > 0
    # Surfaces at two temperatures: no uniform rest state, every step is solved.
    s2 = S.Solver(_air_probe(top_K=300.0, side_K=290.0), 0.01)
    assert s2._rest_range() is None
    T3, _, _ = s2.step(s2.initial_field(300.0), s2.heater_source_W(), 0.0)
    assert T3.min() < 300.0


def test_an_unheated_field_that_is_not_uniform_is_solved_without_a_rest_check():
    # The rest check costs a step of the scheme (and the factor): a field that cannot be at rest
    # (a touch's contact transient) is told by its values alone, and solves to the same bits.
    s = S.Solver(_air_probe(), 0.01, factor_now=False)
    T0 = s.initial_field(300.0)
    T0.flat[int(np.flatnonzero(s.grid.active)[50])] += 0.5
    assert not s._at_rest(T0, 0.0) and s._rest_key is None and s._fac is None
    T1, _, _ = s.step(T0, s.heater_source_W(), 0.0)
    assert s._rest_key is None
    ref = S.Solver(_air_probe(), 0.01).run(T0, 1, keep_field=True).T_final_K
    assert np.array_equal(T1, ref)
    # A uniform field still asks (and is at rest at the surfaces' temperature).
    assert s._at_rest(s.initial_field(300.0), 0.0) and s._rest_key is s.g_t


def test_the_rest_state_follows_the_forcing_a_step_response_swaps_in():
    # step_response zeroes the ambient forcing for its run; the rest state must not outlive it.
    s = S.Solver(_air_probe(), 0.01)
    lo, hi = s._rest_range()
    assert lo <= 300.0 <= hi and hi - lo < 1e-9
    rec = s.step_response(3)
    assert rec.T_tc_K[-1] > 0 and s._rest_range() == (lo, hi)
    saved = s.g_t
    s.g_t = np.zeros_like(saved)
    try:
        lo0, hi0 = s._rest_range()
        assert lo0 <= 0.0 <= hi0 and hi0 < 1e-9
        assert s._at_rest(np.zeros(s.grid.shape), 0.0) and not s._at_rest(s.initial_field(300.0), 0.0)
    finally:
        s.g_t = saved
    assert s._at_rest(s.initial_field(300.0), 0.0) and not s._at_rest(np.zeros(s.grid.shape), 0.0)


def _eliminated_afresh(system):
    """The factor of ``system`` with no shared block rows to take (every inverse computed)."""
    from firmware_sim.rz import blocktri

    saved = dict(blocktri._ROW_CACHE)
    blocktri.clear_row_cache()
    try:
        return S.BlockTridiagonal(*system)
    finally:
        blocktri.clear_row_cache()
        for k, v in saved.items():
            blocktri._keep_row(k, v)


def test_a_factor_that_takes_another_configurations_leading_rows_solves_bit_for_bit_as_a_fresh_one(cold):
    """Block rows shared between factors (a probe's rows, on another object or in air) are the very
    inverses the elimination would compute: the solve is the same to the last bit, and a change in
    any number a row depends on (a later row's, a row's width) is never answered from another."""
    from firmware_sim.rz import blocktri

    rng = np.random.default_rng(6)
    base = _system(rng, n=10, m=8, short_rows=(0, 1, 2))
    other = [a.copy() for a in base]
    other[0][6:] += 0.25                  # another object under the same probe rows
    other[2][6:] *= 1.5
    narrow = [base[0][:5, :4].copy(), base[1][:5, :3].copy(), base[2][:4, :4].copy()]   # "in air": fewer rows, narrower
    narrow[0][-1] += 0.1
    wider = [a.copy() for a in base]
    wider[1][1, 3] = -0.5                 # row 1 couples one more unknown: its width changes
    blocktri.clear_row_cache()
    first = S.BlockTridiagonal(*base)
    n_rows = len(blocktri._ROW_CACHE)
    rhs = rng.normal(size=(10, 8))
    for system in (other, narrow, wider, base):
        shared = S.BlockTridiagonal(*system)
        fresh = _eliminated_afresh(system)
        r = rhs[: system[0].shape[0], : system[0].shape[1]]
        assert np.array_equal(shared.solve(r), fresh.solve(r))
        ref = np.linalg.solve(_dense(*system), r.reshape(-1)).reshape(r.shape)
        np.testing.assert_allclose(shared.solve(r), ref, rtol=1e-12, atol=1e-13)
    # Each later system added only the rows from its first change on: the other object its rows 6-9,
    # the narrow one its rows 3-4 (row 3 narrower), the wider one rows 1-9, the base again none.
    assert n_rows == 10 and len(blocktri._ROW_CACHE) == 10 + 4 + 2 + 9
    assert first.solve(rhs) is not None
    S.clear_factor_cache()
    assert len(blocktri._ROW_CACHE) == 0
