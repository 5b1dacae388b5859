"""Per-test CPU seconds, a pytest plugin for comparing the suite's cost on a shared machine.

``--durations`` reports wall time, which on a loaded two-core machine says more about the other
processes than about the test. This plugin records, for each test, the CPU time (user + system)
its process spent over the test's setup, call and teardown, its own and that of the children it
waited for (a forked kill-point child, a CLI subprocess)::

    python -m pytest -n 2 -p tests.support.cpu_times --cpu-times=/tmp/cpu -m "not slow"
    python -m tests.support.cpu_times /tmp/cpu            # per-file sums, costliest first
    python -m tests.support.cpu_times /tmp/cpu --tier fast

Each process (an xdist worker, or the only one) writes ``<prefix>.<worker>.tsv``: node id, tier
(``slow``/``fast``) and CPU seconds per line, a ``#process`` line with the process's total and a
``#startup`` line with what it had spent when its collection finished (imports, assertion
rewriting, collecting: each worker's start-up, paid before the first test; ``main`` prints it).
What a test leaves to others is not its own: the daemon threads it started are in its process and
counted, and so are a fork server's children (tests/support/daemon_proc.py), as the server reports
each one's end; the server's own CPU is counted when it is waited for, at the teardown of the last
test of its module that uses it. Not a benchmark: a test
that shares a module fixture pays for it only where the fixture is built.
"""

from __future__ import annotations

import os
import resource
import sys
from collections import defaultdict
from pathlib import Path

import pytest

#: This session's rows (node id, tier, CPU seconds), on its config: a pytest run inside a test (pytester)
#: keeps its own.
_ROWS = pytest.StashKey[list]()
#: The process's CPU seconds when its collection finished.
_STARTUP = pytest.StashKey[float]()


def _cpu_s() -> float:
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    forked = sys.modules.get("tests.support.daemon_proc")  # a fork server's children, as they end
    return (own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime
            + (forked.ForkServer.children_cpu_s if forked else 0.0))


def pytest_addoption(parser):
    parser.addoption("--cpu-times", metavar="PREFIX", default=None,
                     help="write each test's CPU seconds to PREFIX.<worker>.tsv (tests/support/cpu_times.py)")


def pytest_configure(config):
    config.stash[_ROWS] = []


def pytest_collection_finish(session):
    session.config.stash[_STARTUP] = _cpu_s()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    t0 = _cpu_s()
    yield
    item.config.stash[_ROWS].append((item.nodeid, "slow" if item.get_closest_marker("slow") else "fast",
                                     _cpu_s() - t0))


def pytest_sessionfinish(session):
    prefix, rows = session.config.getoption("--cpu-times"), session.config.stash[_ROWS]
    if not prefix or not rows:
        return
    worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
    with open(f"{prefix}.{worker}.tsv", "w", encoding="utf-8") as f:
        f.write(f"#process\t\t{_cpu_s():.3f}\n")
        f.write(f"#startup\t\t{session.config.stash.get(_STARTUP, 0.0):.3f}\n")
        f.writelines(f"{node}\t{tier}\t{cpu:.4f}\n" for node, tier, cpu in rows)


def per_file(prefix: str, tier: str | None = None) -> dict[str, float]:
    """CPU seconds per test file from the files ``prefix`` names (``tier``: ``fast``/``slow``/None for both)."""
    sums: dict[str, float] = defaultdict(float)
    for path in Path(prefix).parent.glob(Path(prefix).name + ".*.tsv"):
        for line in path.read_text(encoding="utf-8").splitlines():
            if line.startswith("#"):
                continue   # the process's total
            node, t, cpu = line.split("\t")
            if tier in (None, t):
                sums[node.split("::")[0]] += float(cpu)
    return dict(sums)


def startup(prefix: str) -> dict[str, float]:
    """Each process's CPU seconds at the end of its collection, by worker name, from the files ``prefix`` names."""
    out = {}
    for path in sorted(Path(prefix).parent.glob(Path(prefix).name + ".*.tsv")):
        for line in path.read_text(encoding="utf-8").splitlines():
            if line.startswith("#startup\t"):
                out[path.name[len(Path(prefix).name) + 1:-len(".tsv")]] = float(line.split("\t")[2])
    return out


def module_costs_text(prefix: str) -> str:
    """The schedule's table (tests/support/module_costs.tsv): per test file its fast and slow tests' CPU seconds."""
    fast, slow = per_file(prefix, "fast"), per_file(prefix, "slow")
    lines = [f"# CPU seconds per test file of its fast and its slow tests (python -m tests.support.cpu_times "
             f"{Path(prefix).name} --module-costs): what tests/support/schedule.py orders each worker's quick modules by"]
    lines += [f"{name}\t{fast.get(name, 0.0):.2f}\t{slow.get(name, 0.0):.2f}" for name in sorted(set(fast) | set(slow))]
    return "\n".join(lines) + "\n"


def main(argv: list[str]) -> int:
    if not argv or argv[0].startswith("-"):
        print("usage: python -m tests.support.cpu_times PREFIX [--tier fast|slow] [--top N] [--module-costs]",
              file=sys.stderr)
        return 2
    if "--module-costs" in argv:
        sys.stdout.write(module_costs_text(argv[0]))
        return 0
    tier = argv[argv.index("--tier") + 1] if "--tier" in argv else None
    top = int(argv[argv.index("--top") + 1]) if "--top" in argv else 30
    sums = per_file(argv[0], tier)
    for name, cpu in sorted(sums.items(), key=lambda kv: -kv[1])[:top]:
        print(f"{cpu:7.2f}  {name}")
    print(f"{sum(sums.values()):7.2f}  all tests ({len(sums)} files)")
    for worker, cpu in startup(argv[0]).items():
        print(f"{cpu:7.2f}  {worker}: start-up (CPU when its collection finished)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
