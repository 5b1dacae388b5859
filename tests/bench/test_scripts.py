"""Every benchmark script imports against today's tree (a renamed module must not break a bench silently).

Each script is imported and has a ``main`` (its module-level code runs). The import of a script whose
module level costs seconds (:data:`COSTLY`) runs with the slow tests; in the fast tier a static check
stands for it: read from the script's source without importing it, every ``import`` and ``from ...
import`` (at module level or inside a function) names a module that exists and, for the project's own
modules, a name that module defines (a module already imported is asked, another one's source is read).
"""

from __future__ import annotations

import ast
import importlib
import importlib.util
import sys
from functools import lru_cache
from pathlib import Path

import pytest

# Importing gate_bench imports scikit-learn: one worker pays for it (tests/support/schedule.py).
pytestmark = pytest.mark.shares_import("sklearn")

BENCH = Path(__file__).resolve().parents[2] / "bench"
SCRIPTS = sorted(p.stem for p in BENCH.glob("*_bench.py"))
HELPERS = sorted(p.stem for p in BENCH.glob("_*.py"))
#: Scripts whose import costs seconds of CPU, and why: imported with the slow tests only.
COSTLY = {"gate_bench": "host.train imports scikit-learn (1.3 s of CPU; no fast test needs it)"}
#: The top-level packages whose imported names are checked (the project's, and the bench's own modules).
PROJECT = {"edge", "host", "firmware_sim", "thermotouch_models", "tests"} | set(SCRIPTS) | set(HELPERS)


def test_there_are_benches():
    assert len(SCRIPTS) >= 10 and set(COSTLY) <= set(SCRIPTS)


def _source_of(module: str) -> Path | None:
    """The source file of ``module`` (dotted), found without importing anything below its top-level package."""
    top, *rest = module.split(".")
    spec = importlib.util.find_spec(top)
    if spec is None:
        return None
    if not rest:
        return Path(spec.origin) if spec.origin else None
    path = Path(list(spec.submodule_search_locations)[0]).joinpath(*rest)
    for candidate in (path / "__init__.py", path.with_suffix(".py")):
        if candidate.is_file():
            return candidate
    return None


@lru_cache(maxsize=None)
def _top_level_names(source: Path) -> frozenset[str]:
    """The names the module at ``source`` binds at its top level (definitions, assignments, imports; inside
    if/try/with too)."""
    names: set[str] = set()
    stack = list(ast.parse(source.read_text(encoding="utf-8")).body)
    while stack:
        node = stack.pop()
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign, ast.AugAssign)):
            for target in node.targets if isinstance(node, ast.Assign) else [node.target]:
                names.update(n.id for n in ast.walk(target) if isinstance(n, ast.Name))
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names.update((a.asname or a.name).split(".")[0] for a in node.names)
        elif isinstance(node, (ast.If, ast.Try, ast.With)):
            stack.extend(node.body + getattr(node, "orelse", []) + getattr(node, "finalbody", [])
                         + [n for h in getattr(node, "handlers", []) for n in h.body])
    return frozenset(names)


def _unresolved(path: Path) -> list[str]:
    """What the imports in ``path`` name that today's tree does not have (empty: all resolve)."""
    missing = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            wanted = [(a.name, None) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module != "__future__":
            wanted = [(node.module, a.name) for a in node.names]
        else:
            continue
        for module, name in wanted:
            top = module.split(".")[0]
            if top not in PROJECT:
                if importlib.util.find_spec(top) is None:
                    missing.append(module)
                continue
            source = _source_of(module)
            if source is None:
                missing.append(module)
                continue
            if name is None or name == "*":
                continue
            loaded = sys.modules.get(module)
            if loaded is not None:
                found = hasattr(loaded, name)
            else:
                defined = _top_level_names(source)
                found = name in defined or "__getattr__" in defined
            if not found and _source_of(f"{module}.{name}") is None:
                missing.append(f"{module}.{name}")
    return missing


@pytest.mark.parametrize("name", sorted(COSTLY))
def test_every_name_a_costly_bench_imports_exists_in_todays_tree(name):
    assert _unresolved(BENCH / f"{name}.py") == []


def test_the_static_check_finds_a_renamed_module_and_a_renamed_name(tmp_path):
    script = tmp_path / "x_bench.py"
    script.write_text("import numpy\nfrom host.plots import plot_touch\n\ndef main():\n"
                      "    from host.plots import plot_tuch\n    from host.plotz import plot_touch\n"
                      "    import edge.physics.forwardd\n")
    assert _unresolved(script) == ["host.plots.plot_tuch", "host.plotz", "edge.physics.forwardd"]


@pytest.mark.parametrize("name", [pytest.param(s, marks=pytest.mark.slow) if s in COSTLY else s for s in SCRIPTS])
def test_bench_imports_and_has_a_main(name):
    mod = importlib.import_module(name)
    assert callable(getattr(mod, "main", None)), f"bench/{name}.py has no main()"
    doc = mod.__doc__ or ""
    assert "Run:" in doc or "Usage" in doc, f"bench/{name}.py does not say how to run it"


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
