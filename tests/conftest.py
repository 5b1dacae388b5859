"""Suite-wide fixtures and hooks.

Two tiers: the README's test command, ``python -m pytest -n 2``, runs everything (CI runs exactly
that); the fast tier, ``python -m pytest -n 2 -m "not slow"``, leaves out the tests marked
``slow`` (long simulations, retrains, many daemon runs) for a quick local loop. Targets on this
two-core machine class when it is quiet: 60 s and 20 s of wall time (``bench/suite_bench.py``
measures both). Both pass on a loaded machine: a test waits for what it needs (an event,
``tests.support.waiting.wait_until``, a simulator clock) rather than for a span of wall time, and
a wall-time bound it asserts is a deadline with room for a machine several times slower.
"""

import atexit
import gc
import importlib
import math
import os
import sys
import tempfile
from pathlib import Path

from host.blas import limit_blas_threads, set_blas_env
from tests.support.scratch import MEMORY_ROOT, NEED_BYTES, memory_scratch_root

# The suite starts dozens of daemon and CLI processes. Where PYTHONDONTWRITEBYTECODE is set (some
# sandboxes and CI images set it) each of them would compile edge/ from source again, and pytest
# would re-rewrite every test module in each xdist worker: cache bytecode as an installed device
# does (the systemd deployment compiles at install time, README).
os.environ.pop("PYTHONDONTWRITEBYTECODE", None)
sys.dont_write_bytecode = False

set_blas_env()  # before NumPy loads OpenBLAS, and for the suite's child processes

# The cyclic collector's youngest generation is examined every 20 000 net allocations instead of
# 700: a worker of the fast tier spent 1.2 CPU-s in ~1 000-2 600 collections (gc.callbacks), most
# of them finding nothing, since reference counting frees the suite's objects; at 20 000 it spent
# 0.8 s in ~280. Cyclic garbage still goes, a little later (a test that needs it gone at once
# calls gc.collect(), as tests/firmware_sim/test_pwm.py does). Forked children inherit it; started ones don't.
gc.set_threshold(20_000, 20, 20)


def _scratch_in_memory(root: Path = MEMORY_ROOT, need_bytes: int = NEED_BYTES) -> str | None:
    """Put the suite's ``tmp_path`` directories on a RAM file system when the machine has one.

    The suite writes ~5 400 scratch files (44 MB: histories, bundles, calibrations, the kill-point
    daemons' stores), many of them fsync'ed as the device does. On this project's two-core machine
    class the disk is ext4 mounted with ``discard``: deleting one earlier run's scratch (pytest keeps
    three and deletes the oldest at the start of a run) took 10 s of wall time with 0.4 s of CPU, and
    the kill-point and storage tests ran 21.8 s on it against 13.1 s on tmpfs for the same CPU. The
    behaviour under test is unchanged: the durability tests kill processes (``kill -9``), they do not
    cut the power. Set ``PYTEST_DEBUG_TEMPROOT`` (pytest's own override) to choose another place;
    a RAM file system with less than ``need_bytes`` free is left alone (a container's 64-MB
    /dev/shm). Returns the root chosen, or None.
    """
    if os.environ.get("PYTEST_DEBUG_TEMPROOT") or memory_scratch_root(root, need_bytes) is None:
        return None
    os.environ["PYTEST_DEBUG_TEMPROOT"] = str(root)  # read when the first tmp_path is made; workers inherit it
    # What the code under test makes with ``tempfile`` (each simulated device's PWM sysfs tree, the
    # simulator's work directories, the kill-point templates) goes there too, for the same reason.
    scratch = root / f"thermotouch-tests-{os.getuid()}"
    scratch.mkdir(mode=0o700, exist_ok=True)
    os.environ["TMPDIR"] = str(scratch)
    tempfile.tempdir = None  # forget a temp dir chosen before this ran
    return str(root)


_scratch_in_memory()


if os.environ.get("PYTEST_XDIST_WORKER"):
    from tests.support.worker_exit import exit_without_teardown

    # Registered first, so it runs last of the exit handlers (they run in reverse): tests/support/worker_exit.py.
    atexit.register(exit_without_teardown, os.getpid())

import pytest  # noqa: E402

from tests.support.rewrite_share import quicker_location_fix  # noqa: E402

quicker_location_fix()  # before collection rewrites the test modules


@pytest.fixture(scope="session", autouse=True)
def _one_blas_thread():
    """One BLAS thread for the whole suite (host/blas.py is the one place that sets it)."""
    limit_blas_threads()
    yield


@pytest.fixture(scope="session", autouse=True)
def faithful_world_test_step():
    """The faithful world marches at ``TEST_DT_s`` (tests/support/faithful.py) unless a test chooses.

    Session-scoped, so module and session fixtures that build worlds get it too.
    """
    from firmware_sim.rz.probe_world import FaithfulWorld
    from tests.support.faithful import TEST_DT_s

    with pytest.MonkeyPatch.context() as mp:
        mp.setitem(FaithfulWorld.__init__.__kwdefaults__, "dt_s", TEST_DT_s)
        mp.setitem(FaithfulWorld.for_scene.__func__.__kwdefaults__, "dt_s", TEST_DT_s)
        yield


def _refits_cost_nothing() -> float:
    """A refit timer under which every refit takes no time (see :func:`refits_at_their_nominal_pace`)."""
    return 0.0


@pytest.fixture(scope="session", autouse=True)
def refits_at_their_nominal_pace():
    """Running decisions refit every ``every_s`` of heating, whatever the host's load.

    ``RefitCadence`` stretches the interval when the refits take more than their share of the
    time, timed on the wall clock (``time.perf_counter``). Right on a device, where a refit costs
    real time; but under the simulator's virtual clock the host's load then decides when the
    refits fall, and with them the running answer (at a load of 15 a calibrated glass touch ended
    on a stale running answer, steel). A cadence built with that default timer gets one under
    which a refit costs nothing; the tests of the stretching pass their own timer.
    """
    import time

    from edge.estimation.running import RefitCadence

    real_init = RefitCadence.__init__

    def init(self, *args, timer=time.perf_counter, **kwargs):
        real_init(self, *args, timer=_refits_cost_nothing if timer is time.perf_counter else timer, **kwargs)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(RefitCadence, "__init__", init)
        yield


@pytest.fixture(scope="session", autouse=True)
def _shared_simulated_records(tmp_path_factory):
    """Simulated reference touches computed once per session (tests/support/records.py), kept in its tmp dir."""
    from tests.support import records

    records.cache_dir = records.session_cache_dir(tmp_path_factory.getbasetemp())
    yield
    records.cache_dir = None


@pytest.fixture
def rng():
    # NumPy imported here, not at the top: the xdist controller loads this file before it starts
    # the workers and never needs NumPy (0.1 s before the first worker starts).
    import numpy as np

    return np.random.default_rng(12345)


@pytest.hookimpl(tryfirst=True)
def pytest_collection(session):
    """On a fresh checkout, share pytest's assertion rewriting and the project's compiling between the xdist workers.

    See tests/support/rewrite_share.py.  A module imported here is the one collection uses (same
    name, same file); one that fails to import is left to collection to import again and report.
    Only for the whole suite (the configured ``testpaths``) and where pytest rewrites and caches.
    """
    from tests.support.rewrite_share import compile_missing, modules_to_warm, sources_to_compile

    config = session.config
    if (config.getoption("assertmode") != "rewrite" or sys.dont_write_bytecode
            # Other import modes name (or load) a test module differently from a plain import.
            or str(config.getoption("importmode")) != "prepend"
            or getattr(config, "args_source", None) is not pytest.Config.ArgsSource.TESTPATHS):
        return None
    from tests.support.static_marks import excluded_by

    worker = os.environ.get("PYTEST_XDIST_WORKER", "")
    n = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1") or 1)
    compile_missing(sources_to_compile(Path(__file__).resolve().parents[1], worker, n))
    for name in modules_to_warm(Path(__file__).resolve().parent, worker, n,
                                skip=excluded_by(config.option.markexpr)):
        try:
            importlib.import_module(name)
        except (Exception, pytest.skip.Exception, pytest.fail.Exception):
            pass  # collection imports it again and reports the error or the skip
    return None


def pytest_ignore_collect(collection_path, config):
    """Leave out a test module whose every test ``-m`` would deselect, known from its ``pytestmark`` line.

    The fast tier (``-m "not slow"``) then neither imports nor, on a fresh clone, assertion-rewrites
    the modules that are slow as a whole (tests/support/static_marks.py); the tests that run are
    the same. None (no opinion) for everything else, so pytest's own rules still apply.
    """
    if not (collection_path.name.startswith("test_") and collection_path.suffix == ".py"):
        return None
    from tests.support.static_marks import excluded_module

    return True if excluded_module(collection_path, config.option.markexpr) else None


def _shares_with_another_module(item) -> bool:
    """Whether the schedule keeps ``item``'s module on the worker of the others that share with it: a costly
    import (``shares_import``) or work a process-wide memo keeps for another module (``shares_memo``)."""
    return item.get_closest_marker("shares_import") is not None or item.get_closest_marker("shares_memo") is not None


@pytest.hookimpl(trylast=True)  # after -m/-k deselection: the slices are sized on what runs
def pytest_collection_modifyitems(session, config, items):
    """Each xdist worker's first share of the tests starts with its share of the slow modules.

    See tests/support/schedule.py: long tests first on every worker and quick ones at the end, where
    they fill the gaps (the classic longest-first schedule), and the ``worksteal`` schedule
    (pyproject.toml) lets a worker that ran out take the back half of the other's queue, so the run
    ends on both workers together.  The order is the same on every worker (a function of the
    collection and the worker count), as xdist requires.
    """
    from tests.support.schedule import long_first_slices, read_module_costs

    n = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1") or 1)
    is_slow = lambda item: item.get_closest_marker("slow") is not None  # noqa: E731
    # A module's recorded CPU seconds for the tiers of its selected tests (tests/support/module_costs.tsv); one the
    # table does not know (a new module) could be long: it goes first rather than end a worker's queue.
    table, cost = read_module_costs(Path(__file__).resolve().parent / "support" / "module_costs.tsv"), {}
    for item in items:
        fast_s, slow_s = table.get(item.nodeid.split("::", 1)[0], (math.inf, math.inf))
        cost[item.module] = max(cost.get(item.module, 0.0), fast_s + (slow_s if is_slow(item) else 0.0))
    items[:] = long_first_slices(items, n, module_of=lambda item: item.module, is_slow=is_slow,
                                 shares_import=_shares_with_another_module,
                                 module_cost=lambda module: cost.get(module, 0.0))


def pytest_configure(config):
    config.addinivalue_line(
        "markers", "shares_import(name): the test imports a library that costs ~0.5 s or more of CPU (scikit-learn, scipy.stats, "
        "matplotlib); the xdist schedule gives all such modules to one worker (tests/support/schedule.py)")
    config.addinivalue_line(
        "markers", "shares_memo(name): the test repeats work of another module's tests on the same inputs (a calibration "
        "fit), which a process-wide memo keeps (edge.physics.memo.BoundedMemo): the xdist schedule gives such modules to "
        "one worker, as for shares_import, so that the work is done once")
    from tests.support.hypothesis_summary import summary_only_with_news

    summary_only_with_news(config.pluginmanager)




def pytest_collection_finish(session):
    """Freeze what collection built before the first test runs.

    The imported modules, test functions and fixture definitions live for the whole run; frozen,
    the cyclic collector's full collections (a tenth of a second each in a worker that has
    imported the suite) stop walking them again and again. Objects the tests create are
    collected as before.
    """
    gc.collect()
    gc.freeze()
