"""An xdist worker skips the interpreter's teardown at its exit; a process forked from it does not (tests/support/worker_exit.py)."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

PROGRAM = r"""
import atexit, os, sys
from tests.support.worker_exit import exit_without_teardown

class Teardown:
    def __del__(self):  # runs in the interpreter's teardown only
        os.write(1, b"teardown ")

keep = Teardown()
atexit.register(exit_without_teardown, os.getpid())
atexit.register(lambda: print("later-registered handler ran", end=" ", flush=False))
child = os.fork()
if child == 0:
    sys.exit(5)          # the forked child: its own exit, status and teardown
_, status = os.waitpid(child, 0)
print("child", os.waitstatus_to_exitcode(status), end=" ")
sys.exit(3)              # the worker: exit handlers, then no teardown, status 0
"""


def test_the_worker_ends_after_its_handlers_without_teardown_and_a_forked_child_keeps_its_own_exit():
    # -S: no site packages needed (the module imports the standard library only), a quicker start.
    r = subprocess.run([sys.executable, "-S", "-c", PROGRAM], cwd=ROOT, capture_output=True, text=True, timeout=60)
    # The child (forked after the handlers were registered) ran the later handler, tore down and exited 5; the
    # worker ran the later handler too (its output flushed), then ended with 0 instead of 3 and without teardown.
    assert r.returncode == 0, r
    assert r.stdout == "later-registered handler ran teardown child 5 later-registered handler ran ", r.stdout
