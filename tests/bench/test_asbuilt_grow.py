"""Growing the tactile as-built bench (bench/_asbuilt_grow.py): which drawn probes a run reads."""

from __future__ import annotations



def _meta(probe, names, kind="touch"):
    return [{"probe": probe, "kind": "reference", "name": "pmma", "j": None}] + \
        [{"probe": probe, "kind": kind, "name": n, "j": 1000 * probe} for n in names]


def test_a_probe_cut_short_in_one_file_but_complete_in_another_is_read_and_not_called_incomplete(tmp_path):
    import _asbuilt_grow as G  # bench/ is on the path: tests/bench/conftest.py
    import _asbuilt_touches as A

    names = ["a", "b"]
    base = tmp_path / "tactile_asbuilt_paper.npz"
    A.save_records(base, [None] * 3, _meta(1, names), {"sim_s": 1.0})
    # An earlier run cut short: probe 5 touched only "a"; probe 6 complete.
    m_old = _meta(5, ["a"]) + _meta(6, names)
    A.save_records(G.probes_path(base, 4, 9), [None] * len(m_old), m_old, {"cpu_s": 2.0})
    # A later run drew probe 5 again and finished it; probe 7 it cut short.
    m_new = _meta(5, names) + _meta(7, ["b"])
    A.save_records(G.probes_path(base, 5, 7), [None] * len(m_new), m_new, {"cpu_s": 3.0})
    recs, meta, info = G.load_all(base, names)
    assert {m["probe"] for m in meta} == {1, 5, 6}
    assert sum(m["probe"] == 5 and m["kind"] == "touch" for m in meta) == 2   # each touch once
    assert info["incomplete_probes"] == [7]
    assert info["probes_cpu_s"] == 5.0 and len(recs) == len(meta)


def test_parts_run_side_by_side_merge_to_the_longest_wall_and_the_summed_cpu(tmp_path):
    import _asbuilt_grow as G
    import _asbuilt_touches as A

    base = tmp_path / "tactile_asbuilt_paper.npz"
    for i, (wall, cpu, probe) in enumerate(((100.0, 60.0, 4), (120.0, 70.0, 5)), 1):
        m = _meta(probe, ["a"])
        A.save_records(G.probes_path(base, 4, 5, (i, 2)), [None] * len(m), m, {"sim_s": wall, "cpu_s": cpu})
    (merged,) = G.merge_probes(base)
    _, meta, info = A.load_records(merged)
    assert info["sim_s"] == 120.0 and info["cpu_s"] == 130.0 and {m["probe"] for m in meta} == {4, 5}
    assert not list(tmp_path.glob("*_part*"))


def test_both_touches_of_each_reference_survive_a_merge_and_a_load(tmp_path):
    """Each reference is touched twice (two hands): keyed by name alone, the second touch was dropped."""
    import _asbuilt_grow as G
    import _asbuilt_touches as A

    names = ["a"]
    base = tmp_path / "tactile_asbuilt_paper.npz"
    A.save_records(base, [None] * 2, _meta(1, names), {"sim_s": 1.0})
    refs = [{"probe": 4, "kind": "reference", "name": n} for n in ("pmma", "pmma", "steel", "steel")]
    m = refs + [{"probe": 4, "kind": "touch", "name": "a", "j": 4000}]
    A.save_records(G.probes_path(base, 4, 5, (1, 2)), [None] * len(m), m, {"sim_s": 1.0, "cpu_s": 1.0})
    (merged,) = G.merge_probes(base)
    _, meta, _ = A.load_records(merged)
    assert [x["name"] for x in meta if x["kind"] == "reference"] == ["pmma", "pmma", "steel", "steel"]
    _, meta, _ = G.load_all(base, names)
    assert sum(x["probe"] == 4 and x["kind"] == "reference" for x in meta) == 4
    assert G.record_keys(refs)[1] == (4, "reference", "pmma", 1)
