import os
import sys

from host.blas import limit_blas_threads, set_blas_env

# The suite starts dozens of daemon and CLI processes. Where PYTHONDONTWRITEBYTECODE is set (some
# sandboxes and CI images set it) each of them would compile edge/ from source again, and pytest
# would re-rewrite every test module in each xdist worker: cache bytecode as an installed device
# does (the systemd deployment compiles at install time, README).
os.environ.pop("PYTHONDONTWRITEBYTECODE", None)
sys.dont_write_bytecode = False

set_blas_env()  # before NumPy loads OpenBLAS, and for the suite's child processes

import numpy as np  # noqa: E402
import pytest  # noqa: E402


@pytest.fixture(scope="session", autouse=True)
def _one_blas_thread():
    """One BLAS thread for the whole suite (host/blas.py is the one place that sets it)."""
    limit_blas_threads()
    yield


@pytest.fixture
def rng():
    return np.random.default_rng(12345)
