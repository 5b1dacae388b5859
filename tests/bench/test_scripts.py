"""Every benchmark script imports against today's tree (a renamed module must not break a bench silently)."""

from __future__ import annotations

import ast
import importlib
import importlib.util
from pathlib import Path

import pytest

# Importing the benches imports scikit-learn and matplotlib: one worker pays for them (tests/support/schedule.py).
pytestmark = pytest.mark.shares_import("sklearn", "matplotlib")

BENCH = Path(__file__).resolve().parents[2] / "bench"
SCRIPTS = sorted(p.stem for p in BENCH.glob("*_bench.py"))
#: Benches whose import costs a library the fast tier has no other use for: host.train's scikit-learn and
#: SciPy, 0.7 CPU-s, the fast tier's costliest test. The slow tier imports them; the fast tier reads their
#: imports and checks each against the tree without running them (test_a_costly_bench_s_imports_resolve).
COSTLY_TO_IMPORT = {"gate_bench"}
#: Top-level packages of this project (and bench/'s own modules): their names are checked, not only found.
PROJECT = ("edge", "host", "firmware_sim", "tests", "thermotouch_models")


def test_there_are_benches():
    assert len(SCRIPTS) >= 10


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow) if n in COSTLY_TO_IMPORT else n
                                  for n in SCRIPTS])
def test_bench_imports_and_has_a_main(name):
    mod = importlib.import_module(name)
    assert callable(getattr(mod, "main", None)), f"bench/{name}.py has no main()"
    doc = mod.__doc__ or ""
    assert "Run:" in doc or "Usage" in doc, f"bench/{name}.py does not say how to run it"


def _top_level(tree: ast.Module, skip_optional: bool = False):
    """The statements a module runs when imported: its body and its if/try/with/for blocks', not a def's or class's.

    ``skip_optional``: leave out the body of a ``try`` that catches ImportError (an optional import).
    """
    todo = list(tree.body)
    while todo:
        node = todo.pop(0)
        yield node
        if isinstance(node, (ast.If, ast.Try, ast.With, ast.For, ast.While)):
            optional = isinstance(node, ast.Try) and any(
                isinstance(n, ast.Name) and n.id in ("ImportError", "ModuleNotFoundError")
                for h in node.handlers if h.type is not None for n in ast.walk(h.type))
            todo[:0] = [*(() if optional and skip_optional else node.body), *getattr(node, "orelse", ()),
                        *getattr(node, "finalbody", ()), *(s for h in getattr(node, "handlers", ()) for s in h.body)]


def _imports_run_on_import(tree: ast.Module) -> list[tuple[str, tuple[str, ...]]]:
    """``(module, names)`` of every absolute import a module runs when imported, optional ones (try/ImportError) aside."""
    out = []
    for node in _top_level(tree, skip_optional=True):
        if isinstance(node, ast.Import):
            out += [(a.name, ()) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0:
            out.append((node.module, tuple(a.name for a in node.names)))
    return out


def _bound_at_top(tree: ast.Module) -> set[str]:
    """Names a module's top level binds: defs, classes, assignments, loop targets and imports (``*``: unknown)."""
    names: set[str] = set()
    for node in _top_level(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names.update((a.asname or a.name).split(".")[0] for a in node.names)
        elif isinstance(node, (ast.Assign, ast.AnnAssign, ast.AugAssign, ast.For, ast.With)):
            targets = (node.targets if isinstance(node, ast.Assign) else [i.optional_vars for i in node.items]
                       if isinstance(node, ast.With) else [node.target])
            names.update(n.id for t in targets if t is not None for n in ast.walk(t) if isinstance(n, ast.Name))
    return names


def _unresolved(module: str, names: tuple[str, ...]) -> list[str]:
    """What of ``from module import names`` (or ``import module``) today's tree does not have, read without importing
    it: a project module must exist and bind each name (or have it as a submodule); another library must be
    installed (found without importing its parent packages). Where the source says ``*``, the module is imported."""
    top = module.split(".")[0]
    if top not in PROJECT and not (BENCH / f"{top}.py").exists():
        return [] if importlib.util.find_spec(top) is not None else [module]
    spec = importlib.util.find_spec(module)
    if spec is None or not spec.origin or not spec.origin.endswith(".py"):
        return [module]
    bound = _bound_at_top(ast.parse(Path(spec.origin).read_bytes()))
    missing = [n for n in names if n not in bound and n != "*"
               and not (spec.submodule_search_locations and importlib.util.find_spec(f"{module}.{n}"))]
    if missing and "*" in bound:
        mod = importlib.import_module(module)
        missing = [n for n in missing if not hasattr(mod, n)]
    return [f"{module}.{n}" for n in missing]


@pytest.mark.parametrize("name", sorted(COSTLY_TO_IMPORT))
def test_a_costly_bench_s_imports_resolve_and_it_has_a_main(name):
    """The fast tier's check of a bench it does not import: every module it imports exists, every name it takes from
    this project is there, it has a ``main`` and says how to run it. The slow tier imports it (above)."""
    tree = ast.parse((BENCH / f"{name}.py").read_bytes())
    imports = _imports_run_on_import(tree)
    assert ("host.train", ("train_bundle",)) in imports or name != "gate_bench"   # what made it costly
    assert [u for m, ns in imports for u in _unresolved(m, ns)] == []
    assert any(isinstance(n, ast.FunctionDef) and n.name == "main" for n in tree.body), f"bench/{name}.py has no main()"
    doc = ast.get_docstring(tree) or ""
    assert "Run:" in doc or "Usage" in doc, f"bench/{name}.py does not say how to run it"


def test_the_import_reader_finds_a_renamed_module_or_name():
    tree = ast.parse("import os\nfrom edge.physics.solids import Solid, NoSuchName\ntry:\n    import no_such_lib_s45\n"
                     "except ImportError:\n    pass\nif True:\n    import json\ndef f():\n    import inside_a_def\n"
                     "    local_name = 1\nA, (B, C) = 1, (2, 3)\n")
    assert _imports_run_on_import(tree) == [("os", ()), ("edge.physics.solids", ("Solid", "NoSuchName")), ("json", ())]
    assert _bound_at_top(tree) == {"os", "Solid", "NoSuchName", "no_such_lib_s45", "json", "f", "A", "B", "C"}
    assert _unresolved("edge.physics.solids", ("Solid", "NoSuchName")) == ["edge.physics.solids.NoSuchName"]
    assert _unresolved("edge.physics.no_such_module", ("x",)) == ["edge.physics.no_such_module"]
    assert _unresolved("edge.physics", ("solids",)) == []            # a submodule
    assert _unresolved("no_such_lib_s45", ()) == ["no_such_lib_s45"] and _unresolved("numpy.linalg", ("norm",)) == []


def test_interleaved_rounds_alternate_the_cases():
    import _common

    order: list[str] = []
    res = _common.interleaved({"a": lambda: order.append("a") or 1, "b": lambda: order.append("b") or 2}, 3,
                              warmup=False)
    assert order == ["a", "b"] * 3
    assert res["a"]["n"] == 3 and res["a"]["result"] == 1 and res["b"]["result"] == 2
    assert res["a"]["min_s"] <= res["a"]["median_s"] <= res["a"]["max_s"]
    with pytest.raises(ValueError):
        _common.interleaved({"a": lambda: 1}, 0)


def test_results_name_the_machine_they_were_measured_on():
    import _common

    m = _common.machine()
    assert m["cpus"] >= 1 and m["cpu"] and m["numpy"]
    # The SIMD level decides NumPy's tanh/exp speed (scalar without AVX-512): it must be recorded.
    assert isinstance(m["simd"], list) and all(isinstance(s, str) for s in m["simd"])
    assert all(isinstance(b, str) and b for b in m["blas"])
