"""The device package imports NumPy and its I/O stack only."""

import subprocess
import sys

# threadpoolctl: host/blas.py limits BLAS threads for host tools; the device never loads it (this check used to
# run a second identical subprocess in tests/host/test_blas.py).
BANNED = ("scipy", "sklearn", "torch", "matplotlib", "tqdm", "host", "firmware_sim", "thermotouch_models",
          "threadpoolctl")


def test_every_edge_module_imports_without_host_only_packages():
    code = (
        "import importlib, pkgutil, sys, edge\n"
        "for m in pkgutil.walk_packages(edge.__path__, 'edge.'):\n"
        "    importlib.import_module(m.name)\n"
        f"print(','.join(sorted(b for b in {BANNED!r} if b in sys.modules)))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "", f"edge pulled in: {out.stdout.strip()}"
