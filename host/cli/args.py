"""Argument parsing: the parser whose errors are one line, and typed converters that check on the host.

Every converter raises :class:`argparse.ArgumentTypeError`, which the parser
turns into ``thermotouch VERB: argument --OPTION: what is wrong`` (exit 2)
before any work starts. Output paths are checked twice: their directory when
parsed (it must exist and take a new file), and whether they already exist
once every argument is known (:func:`check_outputs`: only with
``--overwrite``).
"""

from __future__ import annotations

import argparse
import math
import os
import tempfile
from pathlib import Path
from typing import Callable

from host.cli.errors import EXIT_BAD_INPUT, CliError

__all__ = [
    "Parser", "finite_float", "positive_float", "bounded_float", "positive_int", "non_negative_int", "seed",
    "existing_file", "output_file", "output_dir", "add_output", "check_outputs", "add_device_args",
    "resolve_port", "PORT_ENV",
]

#: Environment variable naming the default serial port of device commands.
PORT_ENV = "THERMOTOUCH_PORT"


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors: :meth:`error` raises :class:`CliError` (exit 2), no usage dump."""

    def error(self, message: str):  # noqa: D102
        raise CliError(message, EXIT_BAD_INPUT, prog=self.prog)

    def _get_value(self, action, arg_string):
        # A converter that touches the file system (a name too long for it, a path through a file) raises
        # OSError: that is the argument's fault, reported like any other (exit 2, the verb's prefix).
        try:
            return super()._get_value(action, arg_string)
        except OSError as exc:
            shown = arg_string if len(arg_string) <= 60 else arg_string[:40] + "..." + arg_string[-12:]
            raise argparse.ArgumentError(action, f"{shown}: {exc.strerror or exc}") from None


# --- numbers ----------------------------------------------------------------------------

def _number(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
    return v


def finite_float(text: str) -> float:
    """A finite number (no nan, no inf)."""
    return _number(text)


def positive_float(text: str) -> float:
    """A finite number > 0."""
    v = _number(text)
    if not v > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text!r}")
    return v


def bounded_float(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
                  hi_open: bool = False) -> Callable[[str], float]:
    """A finite number within ``[lo, hi]`` (``lo_open``/``hi_open``: the bound itself excluded)."""
    def conv(text: str) -> float:
        v = _number(text)
        if lo is not None and (v <= lo if lo_open else v < lo):
            raise argparse.ArgumentTypeError(f"must be {'>' if lo_open else '>='} {lo:g}, got {text!r}")
        if hi is not None and (v >= hi if hi_open else v > hi):
            raise argparse.ArgumentTypeError(f"must be {'<' if hi_open else '<='} {hi:g}, got {text!r}")
        return v
    conv.__name__ = "number"
    return conv


def measure_bound(name: str):
    """A converter with the protocol's bounds of MEASURE's ``name`` argument (one definition, edge.protocol),
    and the bounds as text for the help."""
    from edge.protocol.commands import COMMANDS, Command  # noqa: PLC0415

    f = next(a for a in COMMANDS[Command.MEASURE].args if a.name == name)
    text = f"{'>' if f.lo_open else '>='} {f.lo:g}, <= {f.hi:g}"
    if name == "contact_time_s":
        # The protocol's bound is not the device's: its heater refuses an on-time >= heater.max_on_time_s.
        from edge.service.config import Config  # noqa: PLC0415

        limit = Config().heater.max_on_time_s
        text = f"{'>' if f.lo_open else '>='} {f.lo:g}; the device refuses >= its heater.max_on_time_s, {limit:g} s " \
               "by default"
    return bounded_float(f.lo, f.hi, lo_open=f.lo_open), text


def _integer(text: str) -> int:
    try:
        return int(text, 10)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None


def positive_int(text: str) -> int:
    """A whole number >= 1."""
    v = _integer(text)
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {text!r}")
    return v


def non_negative_int(text: str) -> int:
    """A whole number >= 0."""
    v = _integer(text)
    if v < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text!r}")
    return v


def seed(text: str) -> int:
    """A random seed: a whole number in [0, 2**32 - 1] (what NumPy and scikit-learn accept)."""
    v = _integer(text)
    if not 0 <= v <= 2**32 - 1:
        raise argparse.ArgumentTypeError(f"must be between 0 and {2**32 - 1}, got {text!r}")
    return v


# --- paths ------------------------------------------------------------------------------

def existing_file(text: str) -> Path:
    """A readable regular file."""
    if not text:
        raise argparse.ArgumentTypeError("empty file name")
    p = Path(text)
    if not p.exists():
        raise argparse.ArgumentTypeError(f"no such file: {text}")
    if p.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a directory, not a file")
    try:
        with open(p, "rb"):
            pass
    except OSError as exc:
        raise argparse.ArgumentTypeError(f"cannot read {text}: {exc.strerror}") from None
    return p


def _check_parent(text: str) -> Path:
    if not text:
        raise argparse.ArgumentTypeError("empty path")
    p = Path(text)
    parent = p.parent
    if not parent.is_dir():
        what = "is not a directory" if parent.exists() else "does not exist"
        raise argparse.ArgumentTypeError(f"cannot write {text}: directory {parent} {what}")
    try:  # the only reliable test (root, read-only mounts, /proc): create a file there and remove it
        fd, probe = tempfile.mkstemp(prefix=".thermotouch-", dir=parent)
    except OSError as exc:
        raise argparse.ArgumentTypeError(f"cannot write in {parent}: {exc.strerror}") from None
    os.close(fd)
    os.unlink(probe)
    return p


def output_file(suffixes: tuple[str, ...] | None = None) -> Callable[[str], Path]:
    """A file to write: in an existing writable directory, not a directory, with one of ``suffixes``."""
    def conv(text: str) -> Path:
        p = Path(text)
        if p.is_dir():
            raise argparse.ArgumentTypeError(f"{text} is a directory; give a file name"
                                             + (f" ending in {suffixes[0]}" if suffixes else ""))
        if suffixes and p.suffix.lower() not in suffixes:
            raise argparse.ArgumentTypeError(f"{text}: the file name must end in {' or '.join(suffixes)}")
        return _check_parent(text)
    conv.__name__ = "file"
    return conv


def output_dir(text: str) -> Path:
    """A directory to create: its parent exists and is writable; an existing path must be a directory."""
    p = Path(text)
    if p.exists() and not p.is_dir():
        raise argparse.ArgumentTypeError(f"{text} exists and is not a directory")
    return _check_parent(text)


def probe_name(text: str) -> str:
    """A shipped probe head (a name in :data:`edge.physics.geometry.PROBES`)."""
    from edge.physics.geometry import PROBES  # noqa: PLC0415

    if text not in PROBES:
        raise argparse.ArgumentTypeError(f"unknown probe {text!r}; shipped: {', '.join(PROBES)}")
    return text


def add_output(p: argparse.ArgumentParser, *flags: str, kind: str = "file", suffixes=None, **kw) -> None:
    """Add an output-path option; :func:`check_outputs` refuses it if it exists and ``--overwrite`` is not given."""
    action = p.add_argument(*flags, type=output_dir if kind == "dir" else output_file(suffixes), **kw)
    registered = list(p.get_default("_outputs") or [])
    registered.append((action.dest, flags[0]))
    p.set_defaults(_outputs=tuple(registered))
    if not any("--overwrite" in a.option_strings for a in p._actions):
        p.add_argument("--overwrite", action="store_true",
                       help="replace existing output files or directories (default: refuse)")


def check_outputs(args: argparse.Namespace) -> None:
    """Refuse outputs that exist unless ``--overwrite`` (nothing the user did not create is replaced)."""
    for dest, flag in getattr(args, "_outputs", ()) or ():
        path = getattr(args, dest, None)
        if path is not None and os.path.lexists(path) and not getattr(args, "overwrite", False):
            raise CliError(f"{flag} {path} exists (use --overwrite to replace it)", EXIT_BAD_INPUT)


# --- the probe ----------------------------------------------------------------------------

def add_device_args(p: argparse.ArgumentParser, *, sim_help: str | None = None) -> None:
    """``--port`` (default $THERMOTOUCH_PORT) or ``--sim SCENE``, ``--workdir``, ``--timeout``."""
    src = p.add_mutually_exclusive_group()
    src.add_argument("--port", help=f"serial port of the probe, e.g. /dev/ttyACM0 (default: ${PORT_ENV})")
    src.add_argument("--sim", metavar="SCENE", help=sim_help or
                     "start a simulated probe on SCENE (shipped name or .toml) for the duration")
    p.add_argument("--workdir", default=None, help="with --sim: keep the simulated probe's models and history here")
    p.add_argument("--timeout", type=positive_float, default=3.0, help="reply timeout, s (default 3)")
    p.set_defaults(_device=True)


def resolve_port(args: argparse.Namespace) -> None:
    """Fill ``args.port`` from $THERMOTOUCH_PORT when neither --port nor --sim is given; check --workdir."""
    if args.sim is None and args.port is None:
        env = os.environ.get(PORT_ENV, "").strip()
        if not env:
            raise CliError(f"give --port PORT or --sim SCENE (or set {PORT_ENV})", EXIT_BAD_INPUT)
        args.port = env
    if args.workdir is not None and args.sim is None:
        raise CliError("--workdir is for a simulated probe (--sim SCENE)", EXIT_BAD_INPUT)
