"""The measurement worker on its own: busy while a job runs, join stops a job through the stop event."""

import threading
from types import SimpleNamespace

from edge.service.worker import WORKER_JOIN_s, MeasurementWorker, measurement_budget_s


def test_busy_while_running_and_released_early():
    w = MeasurementWorker(threading.Event())
    go, released = threading.Event(), threading.Event()

    def job():
        go.wait(5)
        w.release()
        released.set()

    w.start(job, "test")
    assert w.busy
    go.set()
    assert released.wait(5)
    w.join(abort=False, timeout_s=5)
    assert not w.busy and not w.stop_event.is_set()


def test_join_with_abort_stops_the_job_and_a_crash_is_contained():
    stop = threading.Event()
    w = MeasurementWorker(stop)

    def job():
        stop.wait(5)
        raise RuntimeError("boom")  # logged by the worker, not raised

    w.start(job, "test")
    w.join(abort=True, timeout_s=5)
    assert stop.is_set() and not w.busy


def test_budget_covers_a_whole_measurement():
    from edge.protocol.commands import MAX_ARM_s, MAX_SETTLE_s

    m = SimpleNamespace(baseline_s=1.0, cooldown_s=5.0, arm_s=0.0, settle_s=1.0)
    h = SimpleNamespace(max_on_time_s=3.0)
    # Whatever a MEASURE may ask for (arming and settling up to the protocol's bounds) fits.
    assert measurement_budget_s(m, h) == 9.0 + MAX_ARM_s + MAX_SETTLE_s + WORKER_JOIN_s
    m.arm_s = 2 * MAX_ARM_s
    assert measurement_budget_s(m, h) == 9.0 + 2 * MAX_ARM_s + MAX_SETTLE_s + WORKER_JOIN_s
