"""An xdist worker ends right after its exit handlers, without the interpreter's teardown.

By the time its exit handlers run, a worker has sent its last report, the controller has told it to
exit, and every ``atexit`` handler registered after :func:`exit_without_teardown` has run (temporary
directories' finalizers, multiprocessing's). What is left is freeing the ~1 000 modules and the
memos the tests filled: 1-3 s of wall time at the end of every run, with the controller waiting for
the workers' processes to end (a cold fast-tier run at load 13: last test to exit 1.8-2.0 s before,
0.7-0.8 s after). ``tests/conftest.py`` registers it in each worker, first of all handlers so that
it runs last.
"""

from __future__ import annotations

import logging
import os
import sys


def exit_without_teardown(worker_pid: int) -> None:
    """``os._exit(0)`` after flushing logging and the standard streams, in the process ``worker_pid`` only.

    A process forked from the worker (the fork server's daemons, tests/support/daemon_proc.py; a
    kill-point child) inherits the handler and is left to its own exit and exit status. The worker's
    own status is 0: its results reach the controller as reports, not as its exit status.
    """
    if os.getpid() != worker_pid:
        return
    logging.shutdown()  # logging's own exit handler was registered before this one: it would run after
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except Exception:  # a closed or broken stream: nothing left to lose
            pass
    os._exit(0)
