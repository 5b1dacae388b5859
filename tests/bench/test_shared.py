"""What the benches share: one block writer, the object sets, and the README's accuracy table built from results."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BENCH = ROOT / "bench"


def test_write_block_replaces_its_block_only(tmp_path):
    import _common

    doc = tmp_path / "results.md"
    doc.write_text("head\n<!-- a:begin -->\nold a\n<!-- a:end -->\nmiddle\n<!-- b:begin -->\nold b\n<!-- b:end -->\n")
    assert _common.write_block("a", "new a\nsecond line\n\n", doc) == doc
    assert doc.read_text() == ("head\n<!-- a:begin -->\nnew a\nsecond line\n<!-- a:end -->\nmiddle\n"
                               "<!-- b:begin -->\nold b\n<!-- b:end -->\n")
    with pytest.raises(SystemExit, match="no <!-- c:begin -->"):
        _common.write_block("c", "x", doc)
    # A tag is matched whole, not as a prefix of another one.
    with pytest.raises(SystemExit):
        _common.write_block("a:b", "x", doc)


#: Where a bench's write_block sends a block, by the path constant it passes (default docs/results.md).
_DOC_OF_CONSTANT = {"SCIENCE_MD": "science"}


def _written_tags() -> dict[str, set[str]]:
    """Literal block tags (or f-string prefixes) each bench writes, by target: README, docs/results.md, docs/science.md."""
    out = {"readme": set(), "results": set(), "science": set()}
    for path in BENCH.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.Call):
                continue
            fn = getattr(node.func, "id", getattr(node.func, "attr", None))     # write_block or _common.write_block
            if fn not in ("write_block", "update_readme") or not node.args:
                continue
            first = node.args[0]
            while isinstance(first, ast.BinOp):      # "tag" + suffix: its left part
                first = first.left
            if isinstance(first, ast.JoinedStr):     # an f-string: its literal prefix
                first = first.values[0] if first.values else None
            if not (isinstance(first, ast.Constant) and isinstance(first.value, str) and first.value):
                continue
            tag = re.match(r"[\w-]+", first.value).group(0)
            target = node.args[2] if len(node.args) > 2 else next(
                (k.value for k in node.keywords if k.arg == "path"), None)
            if fn == "update_readme":
                out["readme"].add(tag)
            else:
                const = target.id if isinstance(target, ast.Name) else None
                out[_DOC_OF_CONSTANT.get(const, "results")].add(tag)
    return out


def test_every_block_a_bench_writes_exists_where_it_writes_it():
    tags = _written_tags()
    readme = (ROOT / "README.md").read_text()
    results = (ROOT / "docs" / "results.md").read_text()
    science = (ROOT / "docs" / "science.md").read_text()
    assert {"suite-bench", "demo-bench", "accuracy"} <= tags["readme"]
    assert len(tags["results"]) >= 15
    assert "design-table" in tags["science"]
    for tag in tags["readme"]:
        assert f"<!-- {tag}:begin -->" in readme, f"README.md has no {tag} block"
    for tag in tags["results"]:
        # calibration_bench writes calibration-bench and calibration-bench-reference (an f-string suffix)
        assert re.search(rf"<!-- {re.escape(tag)}[\w-]*:begin -->", results), f"docs/results.md has no {tag} block"
    for tag in tags["science"]:
        assert f"<!-- {tag}:begin -->" in science, f"docs/science.md has no {tag} block"


def test_shared_bench_modules_import_no_bench():
    for name in ("_common", "_objects", "_recognition"):
        tree = ast.parse((BENCH / f"{name}.py").read_text())
        mods = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
        mods |= {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
        assert not {m for m in mods if m.endswith("_bench")}, f"bench/{name}.py imports a bench"


def test_the_tactile_sets_are_disjoint_and_off_the_library():
    import _objects
    from edge.physics.materials import load_materials

    names = [o.name for o in _objects.IN_SET + _objects.HELD_OUT]
    assert len(names) == len(set(names)) == 27
    assert not set(names) & set(load_materials().names)
    assert set(_objects.SOLIDS).isdisjoint({n for n, _, _ in _objects.REFERENCES})
    assert len(_objects.PROBES) == 8


def test_readme_accuracy_table_is_the_one_built_from_the_results():
    import accuracy_bench

    text = accuracy_bench.table()
    readme = (ROOT / "README.md").read_text()
    block = re.search(r"<!-- accuracy:begin -->\n(.*?)<!-- accuracy:end -->", readme, re.S).group(1)
    assert block.rstrip() == text.rstrip(), "run python bench/accuracy_bench.py --update-readme"


def test_accuracy_rows_come_from_their_results_files():
    import json

    import accuracy_bench

    est = json.loads((BENCH / "results" / "estimation.json").read_text())
    rows = accuracy_bench.paper_ideal_rows(est)
    assert [r["board"].split()[0] for r in rows] == ["precision", "reference"]
    assert rows[0]["e"] == (est["lomo_default"]["ads122c04"]["e"]["median"], est["lomo_default"]["ads122c04"]["e"]["p90"])
    # e of a small-heater touch is k/sqrt(alpha): exact errors in k and alpha give the exact e error.
    sp = {"board": "precision", "summary": {"small-heater": {"2s": {"determined_pct": 50.0}}},
          "rows": [{"probe": "small-heater", "contact_time_s": 2.0, "err_k": 0.21, "err_alpha": 0.0},
                   {"probe": "small-heater", "contact_time_s": 2.0, "err_k": 0.1, "err_alpha": 0.21},
                   {"probe": "paper", "contact_time_s": 2.0, "err_k": 9.0, "err_alpha": 9.0}]}
    (row,) = accuracy_bench.small_heater_rows(sp, contacts=("2s",))
    assert row["answered"] == "2/2"
    assert row["e"][0] == pytest.approx((0.21 + 0.0) / 2)
    assert row["kalpha"] == "measured on 50 %"
