"""The order the suite hands its tests to xdist workers in (tests/support/schedule.py)."""

from tests.support.schedule import long_first_slices, slice_sizes


def _items(spec: str) -> list[tuple[str, int, bool]]:
    """``"a:3s b:2"``: module a with 3 tests (slow), module b with 2 quick ones -> (module, i, slow)."""
    out = []
    for part in spec.split():
        name, rest = part.split(":")
        slow = rest.endswith("s")
        out += [(name, i, slow) for i in range(int(rest.rstrip("s")))]
    return out


def _order(items, n):
    return long_first_slices(items, n, module_of=lambda it: it[0], is_slow=lambda it: it[2])


def test_slice_sizes_are_xdists_first_hand_out():
    assert slice_sizes(10, 2) == [5, 5] and slice_sizes(11, 2) == [5, 6] and slice_sizes(10, 3) == [3, 3, 4]
    assert sum(slice_sizes(2566, 4)) == 2566 and slice_sizes(0, 2) == [0, 0]


def test_each_slice_starts_with_its_share_of_the_slow_modules_then_quick_ones():
    items = _items("q1:4 s1:2s q2:3 s2:3s s3:1s q3:5")
    order = _order(items, 2)
    assert sorted(order) == sorted(items)                      # a permutation: nothing lost or doubled
    first, second = order[:9], order[9:]                       # xdist hands out 9 and 9
    # Slow modules alternate (s1, s3 to the first slice; s2 to the second), each at its slice's front.
    assert [m for m, _, _ in first[:3]] == ["s1", "s1", "s3"] and first[3:] == items[:4] + items[6:8]
    assert [m for m, _, _ in second[:3]] == ["s2"] * 3 and [m for m, _, _ in second[3:]] == ["q2"] + ["q3"] * 5
    # A module's tests keep their order; the quick modules keep the collection's.
    assert [i for m, i, _ in order if m == "q3"] == list(range(5))


def test_no_slow_module_or_one_worker_keeps_the_old_order():
    quick = _items("a:3 b:4 c:1")
    assert _order(quick, 2) == quick and _order(quick, 3) == quick
    mixed = _items("a:2 b:1s c:2 d:2s")
    assert [m for m, _, _ in _order(mixed, 1)] == ["b", "d", "d", "a", "a", "c", "c"]
    assert [m for m, _, _ in _order(mixed, 0)] == ["b", "d", "d", "a", "a", "c", "c"]


def test_slow_modules_larger_than_a_slice_push_the_quick_ones_behind():
    items = _items("s1:6s q:2 s2:1s")
    order = _order(items, 2)                                    # slices of 4 and 5
    assert [m for m, _, _ in order] == ["s1"] * 6 + ["s2", "q", "q"]


def test_modules_sharing_a_costly_import_lead_the_first_slice_together():
    items = _items("q1:3 h1:2 s1:2s q2:3 h2:1s s2:2s q3:3")
    order = long_first_slices(items, 2, module_of=lambda it: it[0], is_slow=lambda it: it[2],
                              shares_import=lambda it: it[0].startswith("h"))
    assert sorted(order) == sorted(items)
    first, second = order[:8], order[8:]                        # xdist hands out 8 and 8
    # h1 and h2 (one of them slow) first on one worker, then that slice's slow module, then quick ones.
    assert [m for m, _, _ in first] == ["h1", "h1", "h2", "s1", "s1", "q1", "q1", "q1"]
    assert [m for m, _, _ in second[:2]] == ["s2", "s2"]
    # One worker: nothing to share, the order is the one without them.
    assert long_first_slices(items, 1, module_of=lambda it: it[0], is_slow=lambda it: it[2],
                             shares_import=lambda it: it[0].startswith("h")) == _order(items, 1)


def test_each_slice_runs_its_quick_modules_costliest_first_and_holds_the_same_tests():
    items = _items("s1:2s a:2 b:3 c:2 d:3 e:2")
    cost = {"a": 0.1, "b": 2.0, "d": 0.5, "e": 2.0}.get                 # c: unknown, free
    plain = _order(items, 2)
    order = long_first_slices(items, 2, module_of=lambda it: it[0], is_slow=lambda it: it[2],
                              module_cost=lambda m: cost(m, 0.0))
    # Slices of 7: the same tests in each, only their order differs.
    assert sorted(order[:7]) == sorted(plain[:7]) and sorted(order[7:]) == sorted(plain[7:])
    # The first: its slow module, then b (2.0 s) before a (0.1 s); the second: e (2.0) and d (0.5) before c (free).
    assert [m for m, _, _ in order] == ["s1"] * 2 + ["b"] * 3 + ["a"] * 2 + ["e"] * 2 + ["d"] * 3 + ["c"] * 2
    assert [i for m, i, _ in order if m == "d"] == [0, 1, 2]            # a module's tests keep their order


def test_the_recorded_costs_are_read_and_a_missing_table_leaves_collection_order(tmp_path):
    from pathlib import Path

    from tests.support.schedule import read_module_costs

    p = tmp_path / "costs.tsv"
    p.write_text("# header\ntests/a/test_x.py\t0.50\t2.00\nbroken line\ntests/test_y.py\tx\t1\n")
    assert read_module_costs(p) == {"tests/a/test_x.py": (0.5, 2.0)}
    assert read_module_costs(tmp_path / "none.tsv") == {}
    ours = read_module_costs(Path(__file__).resolve().parent / "support" / "module_costs.tsv")
    assert len(ours) > 100 and all(k.startswith("tests/") and k.endswith(".py") for k in ours)
