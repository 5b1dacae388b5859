"""One BLAS thread for host tools, benches and this suite (host/blas.py); none of it on the device."""

import json
import os
import subprocess
import sys
from pathlib import Path

from host.blas import BLAS_ENV_VARS

ROOT = Path(__file__).resolve().parents[2]


def test_suite_runs_with_one_blas_thread():
    from threadpoolctl import threadpool_info

    assert all(os.environ.get(v) == "1" for v in BLAS_ENV_VARS)
    pools = [p for p in threadpool_info() if p.get("user_api") == "blas"]
    assert pools and all(p["num_threads"] == 1 for p in pools)


def test_the_console_entry_runs_and_limits_blas_threads():
    """``python -m host.cli model ... --json`` in a fresh process without the suite's variables: the command runs
    (its JSON on stdout) and host.cli.main sets the BLAS limit itself.

    One process for both (tests/host/cli/test_model.py's console-script check ran a second one): the entry
    module runs as ``-m`` runs it (``runpy``, as ``__main__``, the arguments in ``sys.argv``), and the BLAS
    pools are read in that process after it.
    """
    code = (
        "import runpy, sys\n"
        "from threadpoolctl import threadpool_info\n"
        "try:\n"
        "    runpy.run_module('host.cli', run_name='__main__', alter_sys=True)\n"
        "    rc = 'no exit'\n"
        "except SystemExit as stop:\n"
        "    rc = stop.code\n"
        "pools = [p['num_threads'] for p in threadpool_info() if p.get('user_api') == 'blas']\n"
        "print(rc, pools, file=sys.stderr)\n"
    )
    env = {k: v for k, v in os.environ.items() if k not in BLAS_ENV_VARS}
    out = subprocess.run([sys.executable, "-c", code, "model", "--k", "1.097", "--rho", "2458.4", "--c", "809",
                          "--json"], capture_output=True, text=True, timeout=120, env=env, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    rc, pools = out.stderr.strip().splitlines()[-1].split(" ", 1)
    assert rc == "0" and pools != "[]" and set(pools.strip("[]").split(", ")) == {"1"}
    assert json.loads(out.stdout)["T_f_K"][-1] > 0.5


# That edge never imports threadpoolctl is checked with its other host-only packages, in one subprocess that
# imports every edge module: tests/edge/test_imports.py.


def test_a_second_call_with_the_same_limit_does_not_rescan_but_a_new_limit_does(monkeypatch):
    import threadpoolctl

    from host import blas

    calls = []
    monkeypatch.setattr(threadpoolctl, "threadpool_limits", lambda limits: calls.append(limits))
    monkeypatch.setattr(blas, "_applied", None)
    monkeypatch.setattr(blas, "_limiter", blas._limiter)
    for v in BLAS_ENV_VARS:
        monkeypatch.setenv(v, "1")
    monkeypatch.setenv("THERMOTOUCH_BLAS_THREADS", "1")
    assert blas.limit_blas_threads() == 1 and blas.limit_blas_threads() == 1
    assert calls == [1]
    monkeypatch.setenv("THERMOTOUCH_BLAS_THREADS", "2")
    assert blas.limit_blas_threads() == 2 and calls == [1, 2] and os.environ["OPENBLAS_NUM_THREADS"] == "2"
    monkeypatch.setenv("THERMOTOUCH_BLAS_THREADS", "1")
    assert blas.limit_blas_threads() == 1 and calls == [1, 2, 1]
