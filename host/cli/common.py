"""What several verbs share: the probe session, the estimator of a bundle, messages beside progress bars."""

from __future__ import annotations

import contextlib
import sys
from typing import Any, Iterator

from host.cli.args import resolve_port
from host.cli.errors import EXIT_BAD_INPUT, EXIT_RUNTIME, CliError

__all__ = ["device_call", "device_session", "load_estimator", "load_object_set", "say", "note"]

#: Device refusals that are the user's input to fix, not the device's state (exit status 2).
INPUT_CODES = ("MODEL_REJECTED", "BAD_ARGUMENT", "NOT_FOUND")


def device_call(fn, *args, **kw):
    """Run a device request; its refusal becomes one line (exit 2 when it is the input, else 1)."""
    from host.client import DeviceError  # noqa: PLC0415

    try:
        return fn(*args, **kw)
    except DeviceError as exc:
        code = EXIT_BAD_INPUT if exc.code.name in INPUT_CODES else EXIT_RUNTIME
        raise CliError(f"device refused: {exc.message}", code) from None


@contextlib.contextmanager
def device_session(args) -> Iterator[Any]:
    """:func:`host.device.open_device` on ``--port`` (or $THERMOTOUCH_PORT) or ``--sim``.

    Device problems raise :class:`host.device.DeviceUnavailable`, which
    :func:`host.cli.main.main` reports in one line with its exit status.
    """
    from host.device import open_device  # noqa: PLC0415

    resolve_port(args)
    with open_device(args.port, args.sim, workdir=args.workdir, timeout_s=args.timeout) as session:
        yield session


def load_estimator(path, method: str = "default"):
    """``(Estimator, Bundle)`` of a bundle directory (default: the shipped one), verified."""
    from edge.model.bundle import BundleError, load_bundle  # noqa: PLC0415
    from edge.estimation.estimate import Estimator, pipeline_golden_check  # noqa: PLC0415

    if path is None:
        from thermotouch_models import DEFAULT_BUNDLE  # noqa: PLC0415

        path = DEFAULT_BUNDLE
    try:
        bundle = load_bundle(path, golden_check=pipeline_golden_check)
    except BundleError as exc:
        raise CliError(f"bundle {path} refused: {exc}", EXIT_BAD_INPUT) from None
    est = Estimator.from_bundle(bundle)
    if method == "paper" and not est.has_paper:
        raise CliError(f"bundle {path} has no paper network", EXIT_BAD_INPUT)
    return est, bundle


def seam_context(path=None, *, calibration=None, object_set=None, object_set_name: str | None = None,
                 thresholds=None, method: str = "default", **kw):
    """The estimate path's context on a bundle directory (default: the shipped one), as the device builds it.

    ``thresholds``: the ``[measurement]`` quality thresholds (default: the configuration's defaults, which a
    device runs with unless configured otherwise); ``kw``: the other :class:`SeamContext` fields
    (``thickness_m``, ``back``).  The object set is named ``object_set_name`` (default: its label).
    """
    from edge.estimation.seam import SeamContext  # noqa: PLC0415
    from edge.service.config import Config  # noqa: PLC0415

    est, _ = load_estimator(path, method)
    return SeamContext(estimator=est, calibration=calibration, object_set=object_set,
                       object_set_name=object_set_name, thresholds=Config().measurement if thresholds is None
                       else thresholds, **kw)


def load_object_set(path) -> tuple[Any, bytes]:
    """``(ObjectSet, raw bytes)`` of an object-set CSV, parsed by the device's own parser.

    :meth:`edge.recognition.ObjectSet.from_csv_text` is the one
    definition of the format; the host checks a file with it before using or
    uploading it.

    Raises
    ------
    CliError
        One line naming the file, and for a malformed row its line and column
        (the first problem; the count of the others).
    """
    from edge.recognition import ObjectSet, ObjectSetError  # noqa: PLC0415

    try:
        raw = open(path, "rb").read()
    except OSError as exc:
        raise CliError(f"{path}: cannot read: {exc.strerror or exc}") from None
    try:
        text = raw.decode("utf-8-sig")  # a spreadsheet's byte-order mark is fine
    except UnicodeDecodeError as exc:
        raise CliError(f"{path}: not UTF-8 text (byte {exc.start})") from None
    try:
        return ObjectSet.from_csv_text(text, label=str(path)), raw
    except ObjectSetError as exc:
        first, more = exc.issues[0], len(exc.issues) - 1
        raise CliError(f"{path}: {first}" + (f" (and {more} more problem{'s' if more > 1 else ''})" if more else "")) \
            from None
    except ValueError as exc:  # the set as a whole (e.g. no objects)
        raise CliError(f"{path}: {exc}") from None


def say(message: str) -> None:
    """A line of output on stdout, never on the line of a running progress bar."""
    from host.progress import echo  # noqa: PLC0415

    echo(message, file=sys.stdout)


def note(message: str) -> None:
    """A line of commentary on stderr, never on the line of a running progress bar."""
    from host.progress import echo  # noqa: PLC0415

    echo(message, file=sys.stderr)
