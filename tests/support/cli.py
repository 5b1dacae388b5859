"""Running the ``thermotouch`` CLI in process, as the CLI tests do."""

from __future__ import annotations

import contextlib
import io

from host.cli.main import main

__all__ = ["run", "run_captured", "one_line_error", "rounded"]


def run(capsys, *argv):
    """``(exit code, stdout, stderr)`` of ``thermotouch ARGV`` run in this process."""
    code = main([str(a) for a in argv])   # paths as the shell would pass them
    out, err = capsys.readouterr()
    return code, out, err


def run_captured(*argv):
    """:func:`run` without pytest's ``capsys``, for module-scoped fixtures that run a command once.

    ``thermotouch`` writes through ``sys.stdout``/``sys.stderr`` as looked up at call time, so
    redirecting them catches exactly what ``capsys`` would.
    """
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in argv])
    return code, out.getvalue(), err.getvalue()


def one_line_error(err: str) -> str:
    """The one line a refusal prints (no traceback), asserted to be one line."""
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def rounded(v):
    """``v`` with every float to 12 significant digits, however nested (answers compared across processes)."""
    if isinstance(v, float):
        return float(f"{v:.12g}")
    if isinstance(v, dict):
        return {k: rounded(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [rounded(x) for x in v]
    return v
