"""The order the suite's tests are handed to the xdist workers in: each worker's share long-first.

pytest-xdist's ``worksteal`` schedule (pyproject.toml) first hands worker i the i-th of n consecutive
slices of the collection (``len(rest) // (n - i)`` tests each), then lets a worker that ran out take
the back half of the longest queue left.  Putting every module with a ``slow`` test first (the
order before this one) gave them all to the first slice: the other worker ran the quick tests, then
stole the slow ones one half-queue at a time, and the run ended on a long test (a 6-s demo) with the
other worker idle.  Here each slice starts with its share of the slow modules (every n-th, in
collection order) and is filled up with the quick ones: every worker starts long, a steal takes
quick tests from a queue's back, and the run ends on quick tests.  A module's tests stay together
(its module-scoped fixtures are built once per worker) except where a slice boundary or a steal
cuts a quick module.  ``tests/conftest.py`` (``pytest_collection_modifyitems``) uses it.

Modules that import a costly library no other test needs (``shares_import``: scikit-learn, about
1 s of CPU to import; matplotlib, about 0.5 s) go together at the front of the first slice, so that
one worker pays for the import, not each of them (a steal takes from a queue's back).

Within a slice the quick modules go costliest first when their cost is known (``module_cost``: the
CPU seconds a module's selected tests took in a recorded run, tests/support/module_costs.tsv), so
that a queue ends on its cheapest modules: what a steal takes, and what a worker runs last while the
other has nothing left, are then milliseconds, not a 0.6-s test. Which tests a slice holds is the
same; tests/conftest.py gives a module the table does not know an infinite cost (it goes first).
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Sequence
from typing import TypeVar

T = TypeVar("T")


def slice_sizes(n_items: int, n_workers: int) -> list[int]:
    """How many tests xdist's first hand-out gives each worker (its ``len(rest) // (n - i)``)."""
    sizes, rest = [], n_items
    for i in range(n_workers):
        sizes.append(rest // (n_workers - i))
        rest -= sizes[-1]
    return sizes


def _costliest_first(part: list[T], module_of: Callable[[T], Hashable],
                     module_cost: Callable[[Hashable], float] | None) -> list[T]:
    """``part``'s modules by ``module_cost`` descending (ties and unknown costs: their order in ``part``), tests in order."""
    if module_cost is None:
        return part
    groups: dict[Hashable, list[T]] = {}
    for item in part:
        groups.setdefault(module_of(item), []).append(item)
    ranked = sorted(enumerate(groups), key=lambda im: (-module_cost(im[1]), im[0]))
    return [item for _, m in ranked for item in groups[m]]


def long_first_slices(items: Sequence[T], n_workers: int, module_of: Callable[[T], Hashable],
                      is_slow: Callable[[T], bool],
                      shares_import: Callable[[T], bool] = lambda item: False,
                      module_cost: Callable[[Hashable], float] | None = None) -> list[T]:
    """``items`` reordered: slice i holds every n-th slow module, then quick modules up to its size.

    Modules (``module_of``) keep their collection order and their tests' order; a module is slow if
    one of its tests is (``is_slow``).  With one worker (or none) the slow modules simply go first.
    Modules one of whose tests ``shares_import`` lead the first slice, ahead of its slow modules.
    ``module_cost`` (CPU seconds, 0 where unknown): each slice's quick modules costliest first.
    The same input gives the same order, as xdist requires of every worker's collection.
    """
    modules: dict[Hashable, list[T]] = {}
    for item in items:
        modules.setdefault(module_of(item), []).append(item)
    together = [m for m, its in modules.items() if n_workers >= 2 and any(shares_import(i) for i in its)]
    slow = [m for m, its in modules.items() if m not in together and any(is_slow(i) for i in its)]
    slow_set = set(slow) | set(together)
    quick = [i for m, its in modules.items() if m not in slow_set for i in its]
    if n_workers < 2:
        return [i for m in slow for i in modules[m]] + quick
    out: list[T] = [i for m in together for i in modules[m]]
    boundary = 0
    for w, size in enumerate(slice_sizes(len(items), n_workers)):
        boundary += size
        for m in slow[w::n_workers]:
            out.extend(modules[m])
        take = max(0, boundary - len(out))   # a slice already past its size (slow modules) takes none
        out.extend(_costliest_first(quick[:take], module_of, module_cost))
        del quick[:take]
    return out + _costliest_first(quick, module_of, module_cost)


def read_module_costs(path) -> dict[str, tuple[float, float]]:
    """``{test file: (fast-tier CPU-s, slow-tier CPU-s)}`` from a table ``python -m tests.support.cpu_times PREFIX
    --module-costs`` wrote; empty where the file is missing or unreadable (the order is then collection's)."""
    out: dict[str, tuple[float, float]] = {}
    try:
        lines = open(path, encoding="utf-8").read().splitlines()
    except OSError:
        return out
    for line in lines:
        parts = line.split("\t")
        if len(parts) == 3 and not line.startswith("#"):
            try:
                out[parts[0]] = (float(parts[1]), float(parts[2]))
            except ValueError:
                continue
    return out
