"""Signal handlers a test installs in the test process (``install_signal_handlers``) are put back after it."""

import signal

import pytest

from edge.service.main import STOP_SIGNALS


@pytest.fixture(autouse=True)
def _restore_signal_handlers():
    sigs = [*STOP_SIGNALS, signal.SIGTSTP, signal.SIGTTIN, signal.SIGTTOU]
    old = {s: signal.getsignal(s) for s in sigs}
    yield
    for s, h in old.items():
        if h is not None and signal.getsignal(s) is not h:
            signal.signal(s, h)
