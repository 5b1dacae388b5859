"""``thermotouch``: the parser built from the verb modules, and the one error path of the CLI.

Every error a user can meet prints one line on stderr and exits non-zero --
2 for bad arguments or input (checked on the host before any work), 1 for
device or runtime failures, 3 when ``deploy`` refuses a bundle, 130 on
Ctrl-C -- never a traceback (``--log-file`` or ``--verbose`` records it;
``THERMOTOUCH_DEBUG=1`` re-raises it).
"""

from __future__ import annotations

import argparse
import errno
import functools
import logging
import os
import sys

from host.cli import (calibrate, deploy, demo, design, estimate, evaluate, flash, history, info, keys, measure, model, objects,
                       sim, train)
from host.cli import flags, lab_report, series
from host.cli.args import Parser, check_outputs
from host.blas import limit_blas_threads
from host.cli.errors import EXIT_BAD_INPUT, EXIT_INTERRUPTED, EXIT_RUNTIME, CliError

__all__ = ["VERBS", "build_parser", "main", "version"]

#: One module per verb, in the order of ``thermotouch --help``.
VERBS = (measure, info, history, flash, objects, sim, demo, deploy, keys, model, design, train, evaluate, estimate,
         calibrate, series, lab_report, flags)

#: Loggers of this code base (the edge daemon and simulator log under ``thermotouch``).
_LOGGERS = ("thermotouch", "host", "edge", "firmware_sim")

log = logging.getLogger("thermotouch.cli")


def version() -> str:
    """The installed distribution's version."""
    from importlib.metadata import PackageNotFoundError, version as dist_version  # noqa: PLC0415

    try:
        return dist_version("thermotouch")
    except PackageNotFoundError:  # pragma: no cover - run from a checkout without an install
        return "unknown"


def _log_file(text: str) -> str:
    if not text:
        raise argparse.ArgumentTypeError("empty file name")
    if os.path.isdir(text):
        raise argparse.ArgumentTypeError(f"{text} is a directory")
    parent = os.path.dirname(text) or "."
    if not os.path.isdir(parent):
        raise argparse.ArgumentTypeError(f"directory {parent} does not exist")
    return text


@functools.lru_cache(maxsize=1)
def build_parser() -> argparse.ArgumentParser:
    """The ``thermotouch`` parser, built once per process.

    Fifteen verbs' options cost ~10 ms to build, and a program (or the test suite) that calls
    :func:`main` again and again would pay it each time; parsing leaves the parser unchanged
    (no verb mutates a default, ``append`` actions copy theirs).  A verb's ``func`` is bound
    when the parser is built.
    """
    # Options every verb takes, before or after the verb (SUPPRESS: a verb's parser does not reset them).
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("-v", "--verbose", action="store_true", default=argparse.SUPPRESS,
                        help="log what happens (device, daemon, steps) on stderr")
    common.add_argument("--log-file", type=_log_file, default=argparse.SUPPRESS, metavar="FILE",
                        help="append a detailed log (with tracebacks of internal errors) to FILE")
    parser = Parser(prog="thermotouch", description="ThermoTouch contact thermal-property probe", parents=[common],
                    epilog="Bad arguments or input print one line and exit 2; device or runtime failures exit 1. "
                           "Device commands take --port PORT (default $THERMOTOUCH_PORT) or --sim SCENE.")
    parser.add_argument("--version", action="version", version=f"thermotouch {version()}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser, metavar="COMMAND")
    for verb in VERBS:
        verb.add_parser(sub, [common])
    return parser


class _Logging:
    """Handlers for ``--verbose`` / ``--log-file`` on this code base's loggers, removed when main returns."""

    def __init__(self, verbose: bool, log_file: str | None) -> None:
        self.handlers: list[logging.Handler] = []
        fmt = logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s")
        if verbose:
            h = logging.StreamHandler(sys.stderr)
            h.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))
            self.handlers.append(h)
        if log_file:
            try:
                h = logging.FileHandler(log_file, encoding="utf-8")
            except OSError as exc:
                raise CliError(f"argument --log-file: cannot open {log_file}: {exc.strerror}") from None
            h.setFormatter(fmt)
            self.handlers.append(h)
        if not self.handlers:  # without either, library warnings are not a second line on stderr
            self.handlers.append(logging.NullHandler())
        self.saved = {}
        for name in _LOGGERS:
            lg = logging.getLogger(name)
            self.saved[name] = lg.level
            if verbose or log_file:
                lg.setLevel(logging.DEBUG)
            for h in self.handlers:
                lg.addHandler(h)

    def close(self) -> None:
        for name, level in self.saved.items():
            lg = logging.getLogger(name)
            lg.setLevel(level)
            for h in self.handlers:
                lg.removeHandler(h)
        for h in self.handlers:
            h.close()


def _run(argv: list[str] | None) -> tuple[int, str]:
    """Parse and run; returns (status, prog)."""
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:  # --help, --version: printed by argparse
        return (exc.code if isinstance(exc.code, int) else 0), "thermotouch"
    action = getattr(args, f"{args.command}_command", None)  # objects add, keys new: the whole verb says it
    prog = f"thermotouch {args.command}" + (f" {action}" if action else "")
    logs = _Logging(getattr(args, "verbose", False), getattr(args, "log_file", None))
    try:
        log.debug("%s %s", prog, argv if argv is not None else sys.argv[1:])
        check_outputs(args)
        return args.func(args), prog
    except BaseException as exc:
        exc.__thermotouch_prog__ = prog  # noqa: B010 - who reports it
        if not isinstance(exc, (CliError, KeyboardInterrupt)):
            log.debug("%s failed", prog, exc_info=True)
        raise
    finally:
        logs.close()


def _one_line(exc: BaseException, prog: str) -> tuple[str, int]:
    """The user's line and exit status for an exception out of a verb."""
    from host.device import DeviceUnavailable  # noqa: PLC0415

    if isinstance(exc, CliError):
        return f"{exc.prog or prog}: {exc}", exc.code
    if isinstance(exc, DeviceUnavailable):
        return f"{prog}: {exc}", exc.code
    from edge.protocol.errors import ProtocolError  # noqa: PLC0415

    if isinstance(exc, ProtocolError):  # an argument the client refused to send
        return f"{prog}: {exc}", EXIT_BAD_INPUT
    if isinstance(exc, (FileExistsError, NotADirectoryError)):
        return f"{prog}: {exc.args[-1] if exc.args else exc}", EXIT_BAD_INPUT
    if isinstance(exc, MemoryError):
        return f"{prog}: out of memory", EXIT_RUNTIME
    if isinstance(exc, OSError):
        name = str(exc.filename) if exc.filename else ""
        where = f"{name if len(name) <= 60 else name[:40] + '...' + name[-12:]}: " if name else ""
        # A file name the file system cannot take is the user's input, not a runtime failure.
        code = EXIT_BAD_INPUT if exc.errno == errno.ENAMETOOLONG else EXIT_RUNTIME
        return f"{prog}: {where}{exc.strerror or exc}", code
    return (f"{prog}: internal error: {type(exc).__name__}: {exc} "
            "(see --log-file, or set THERMOTOUCH_DEBUG=1 for the traceback)"), EXIT_RUNTIME


def main(argv: list[str] | None = None) -> int:
    """Console script ``thermotouch``; returns the exit status."""
    # One BLAS thread (host/blas.py): on two shared cores OpenBLAS's own threads made training 5x slower.
    limit_blas_threads()
    from host.cli.terminal import NeutralStream, neutralise  # noqa: PLC0415

    real_stdout = sys.stdout
    sys.stdout = NeutralStream(real_stdout)  # for this verb only: an in-process caller gets its own back
    try:
        code, _ = _run(argv)
        return code
    except KeyboardInterrupt:
        print("thermotouch: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:  # output piped into head & co.: stop quietly
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
        except (OSError, ValueError):
            pass
        return 0
    except CliError as exc:
        line, code = _one_line(exc, getattr(exc, "__thermotouch_prog__", "thermotouch"))
    except Exception as exc:  # noqa: BLE001 - the one error path: one line, never a traceback
        line, code = _one_line(exc, getattr(exc, "__thermotouch_prog__", "thermotouch"))
        if " internal error: " in line and os.environ.get("THERMOTOUCH_DEBUG"):
            raise
    finally:
        sys.stdout = real_stdout
    print(neutralise(line.replace("\n", " ")), file=sys.stderr)
    return code


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
