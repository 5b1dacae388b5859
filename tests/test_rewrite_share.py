"""The suite's share-out of assertion rewriting between xdist workers (tests/support/rewrite_share.py)."""

from pathlib import Path

from tests.support.rewrite_share import modules_to_warm


def _tree(root: Path, names: list[str]) -> Path:
    pkg = root / "tests"
    for name in names:
        p = pkg / name
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text("")
    return pkg


def test_the_slices_cover_every_module_once_and_gw0_imports_nothing(tmp_path):
    pkg = _tree(tmp_path, ["test_a.py", "edge/test_b.py", "edge/test_c.py", "host/test_d.py", "host/util.py",
                           "host/cli/test_e.py"])
    assert modules_to_warm(pkg, "gw0", 3) == []
    # Five modules in collection's order (edge/b, edge/c, host/cli/e, host/d, a) in slices of two.
    assert modules_to_warm(pkg, "gw1", 3) == ["tests.host.cli.test_e", "tests.host.test_d"]
    assert modules_to_warm(pkg, "gw2", 3) == ["tests.test_a"]
    # Two workers: gw0's first three (its share rounded up), gw1 the rest; helpers are never imported.
    assert modules_to_warm(pkg, "gw1", 2) == ["tests.host.test_d", "tests.test_a"]
    # Modules collection leaves out (a -m expression's, tests/support/static_marks.py) are in no slice.
    assert modules_to_warm(pkg, "gw1", 2, skip=lambda p: p.name == "test_a.py") == ["tests.host.cli.test_e",
                                                                               "tests.host.test_d"]
    # No sharing without workers, or with one, or for a name that is not a worker's.
    assert modules_to_warm(pkg, "", 1) == modules_to_warm(pkg, "gw1", 1) == modules_to_warm(pkg, "main", 2) == []


def test_this_suites_second_half_is_gw1s_and_importable_by_those_names():
    root = Path(__file__).resolve().parent
    names = modules_to_warm(root, "gw1", 2)
    every = sorted(root.rglob("test_*.py"))
    assert len(names) == len(every) // 2 > 50
    assert __name__ == "tests.test_rewrite_share" and __name__ in names   # importable as collection names it



def _every_node(node):
    """pytest 9's ``traverse_node``: every node, depth-first."""
    import ast

    yield node
    for child in ast.iter_child_nodes(node):
        yield from _every_node(child)


def test_the_quicker_location_fix_rewrites_this_suites_modules_to_the_same_code():
    import ast
    import marshal

    import _pytest.assertion.rewrite as rewrite

    from tests.support.rewrite_share import _located_candidates

    root = Path(__file__).resolve().parent
    # This module, and the one with the most rewritten asserts (84: compares, calls, attributes, msgs).
    sample = [root / "test_rewrite_share.py", root / "edge" / "protocol" / "test_messages.py"]
    before = rewrite.traverse_node
    try:
        outs = []
        for walk in (_every_node, _located_candidates):
            rewrite.traverse_node = walk
            out = []
            for path in sample:
                source = path.read_bytes()
                tree = ast.parse(source, filename=str(path))
                rewrite.rewrite_asserts(tree, source, str(path), None)
                # The code object carries every instruction's line and column span (co_positions).
                out.append(marshal.dumps(compile(tree, str(path), "exec", dont_inherit=True)))
            outs.append(out)
    finally:
        rewrite.traverse_node = before
    assert outs[0] == outs[1]
    # What the fix visits: only nodes that take a location and have none yet.
    tree = ast.parse("assert f(x) == [y for y in z]")
    fresh = ast.BinOp(ast.Name("a", ast.Load()), ast.Add(), ast.Constant(1))
    tree.body.append(ast.Expr(fresh))
    assert [type(n).__name__ for n in _located_candidates(tree)] == ["Expr", "BinOp", "Name", "Constant"]


def test_the_project_sources_are_cut_into_disjoint_slices_of_about_equal_bytes(tmp_path):
    from tests.support.rewrite_share import sources_to_compile

    for name, size in (("edge/a.py", 100), ("edge/b.py", 300), ("host/c.py", 100), ("host/test_d.py", 50),
                       ("tests/conftest.py", 10), ("tests/support/e.py", 100), ("bench/f.py", 10)):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text("x = 1\n" + "#" * (size - 6) + "\n")
    pkgs = ("edge", "host", "tests")
    shares = [sources_to_compile(tmp_path, f"gw{i}", 2, pkgs) for i in range(2)]
    names = [[p.relative_to(tmp_path).as_posix() for p in s] for s in shares]
    # Test modules and conftest files are pytest's to rewrite; bench/ is not a package named here.
    assert names == [["edge/a.py", "edge/b.py"], ["host/c.py", "tests/support/e.py"]]
    assert sources_to_compile(tmp_path, "gw0", 1, pkgs) == sources_to_compile(tmp_path, "main", 2, pkgs) == []
    # This suite's own: both shares together are every helper and package module, once.
    root = Path(__file__).resolve().parents[1]
    ours = [sources_to_compile(root, f"gw{i}", 2) for i in range(2)]
    assert not set(ours[0]) & set(ours[1]) and root / "edge" / "__init__.py" in ours[0]
    assert root / "tests" / "support" / "rewrite_share.py" in ours[0] + ours[1]


def test_a_missing_bytecode_file_is_written_as_import_would_and_an_existing_one_is_left(tmp_path, monkeypatch):
    import importlib.util
    import sys

    from tests.support.rewrite_share import compile_missing

    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1")   # py_compile's default would then be a hash-checked file
    src = tmp_path / "shared_mod_s45.py"
    src.write_text("VALUE = 41 + 1\n")
    bad = tmp_path / "broken_mod_s45.py"
    bad.write_text("def (:\n")
    assert compile_missing([src, bad]) == 1
    cfile = Path(importlib.util.cache_from_source(str(src)))
    data = cfile.read_bytes()
    assert data[:4] == importlib.util.MAGIC_NUMBER and int.from_bytes(data[4:8], "little") == 0   # timestamp-checked
    assert compile_missing([src]) == 0 and cfile.read_bytes() == data
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "shared_mod_s45", raising=False)
    mod = importlib.import_module("shared_mod_s45")
    assert mod.VALUE == 42 and mod.__cached__ == str(cfile) and cfile.read_bytes() == data   # import took it as is
