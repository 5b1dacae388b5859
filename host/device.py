"""Reaching a probe from the host: a real serial port, or a simulated probe for the duration.

:func:`open_device` yields a :class:`DeviceSession` whose ``client`` is a
:class:`host.client.DeviceClient` on a serial port. With ``sim=SCENE`` it
first starts the edge daemon on the scene's simulator in a background thread
behind a real pseudo-terminal pair (:func:`firmware_sim.run.run_sim`), so the
host talks to it exactly as to a probe on ``/dev/ttyACM0``; the daemon is
stopped (heater off, history closed) when the block ends.

Every failure a user can meet is raised as :class:`DeviceUnavailable` with a
one-line message (the CLI prints it and exits non-zero): no such port, port
busy, device not answering, device refusing, invalid scene.
"""

from __future__ import annotations

import contextlib
import logging
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

from host.client import BadReply, ClientError, DeviceClient, DeviceError, DeviceNotAnswering, PortUnavailable

__all__ = ["DeviceUnavailable", "DeviceSession", "open_device", "describe_error", "SIM_START_TIMEOUT_s"]

#: Longest wait for a simulated probe to answer, s (daemon start-up is well under a second).
SIM_START_TIMEOUT_s = 20.0


class DeviceUnavailable(Exception):
    """A device problem to report to the user in one line; ``code`` is the exit status (2: bad input)."""

    def __init__(self, message: str, code: int = 1) -> None:
        super().__init__(message)
        self.code = code


def describe_error(exc: BaseException, port: str | None = None) -> str:
    """One user-facing line for a client-side exception."""
    where = f" on {port}" if port else ""
    if isinstance(exc, PortUnavailable):
        reason = exc.reason
        low = reason.lower()
        if "exclusively lock" in low or "resource temporarily unavailable" in low or "busy" in low:
            return f"serial port {exc.port} is busy (another program has it open)"
        if "no such file" in low or "could not open port" in low and "errno 2" in low:
            return f"no such serial port: {exc.port}"
        return f"serial port {exc.port} unavailable: {reason}"
    if isinstance(exc, DeviceNotAnswering):
        return (f"device{where} not answering: no reply to {exc.command.name} within {exc.timeout_s:g} s "
                f"(is the probe daemon running on the other end?)")
    if isinstance(exc, DeviceError):
        if exc.code.name == "BUSY":
            return f"device{where} busy: {exc.message}"
        if exc.code.name == "MODEL_REJECTED":
            return f"device{where} refused the bundle: {exc.message}"
        return f"device{where} error {exc.code.name}: {exc.message}" + (f" (field {exc.field})" if exc.field else "")
    if isinstance(exc, BadReply):
        return f"device{where} sent a bad reply: {exc}"
    return f"{type(exc).__name__}: {exc}"


@contextlib.contextmanager
def device_errors(port: str | None = None) -> Iterator[None]:
    """Turn client exceptions inside the block into :class:`DeviceUnavailable`."""
    try:
        yield
    except ClientError as exc:
        # The device refusing an argument or a bundle (bad signature, untrusted key, downgrade, failed
        # checks) is bad input (exit status 2), like the host refusing it.
        bad_arg = isinstance(exc, DeviceError) and exc.code.name in ("BAD_ARGUMENT", "MODEL_REJECTED")
        raise DeviceUnavailable(describe_error(exc, port), 2 if bad_arg else 1) from None


@dataclass
class DeviceSession:
    """An open connection to a probe.

    Attributes
    ----------
    client : DeviceClient
    port : str
        Host-side serial port path.
    daemon, simulator : optional
        The in-process edge daemon and its :class:`firmware_sim.Simulator`
        (only with a simulated probe).
    workdir : Path, optional
        The simulated probe's storage (model store, history).
    """

    client: DeviceClient
    port: str
    daemon: Any = None
    simulator: Any = None
    workdir: Path | None = None
    extra: dict = field(default_factory=dict)

    @property
    def simulated(self) -> bool:
        return self.simulator is not None

    def series(self, measurement_id: int) -> dict:
        """A stored measurement read over the serial link: its record and its series.

        The record's fields (``T0_C``, ``q_offset_W_m2``, ``power_W``,
        ``model_sha256``, ``result`` ...) come from RESULT, the arrays
        ``raw_t_s``, ``raw_T_C``, ``raw_q_W_m2``, ``grid_t_s``,
        ``grid_dT_K``, ``grid_q_W_m2`` from SERIES pages (None for a series
        the device did not store) -- the same for a probe on a port and a
        simulated one.
        """
        out = dict(self.client.result(int(measurement_id)))
        out.update(self.client.series(int(measurement_id)))
        return out


def validate_scene(scene: str) -> Any:
    """Parse a scene file or shipped name; DeviceUnavailable with the scene's own message if invalid."""
    from firmware_sim import SceneError, read_scene  # noqa: PLC0415

    try:
        return read_scene(scene)
    except SceneError as exc:
        raise DeviceUnavailable(f"invalid scene: {exc}", 2) from None
    except (OSError, ValueError) as exc:
        raise DeviceUnavailable(f"invalid scene {scene}: {exc}", 2) from None


@contextlib.contextmanager
def simulated_probe(scene: str, workdir: str | Path | None = None, *,
                    overrides: dict | None = None) -> Iterator[tuple[str, Any, Any]]:
    """Run the edge daemon on ``scene``'s simulator in a thread; yield ``(port, daemon, simulator)``."""
    from firmware_sim.run import run_sim  # noqa: PLC0415

    validate_scene(scene)
    stop = threading.Event()
    ports: list[str] = []
    box: dict[str, Any] = {}
    errors: list[BaseException] = []
    started = threading.Event()  # set once the daemon answers, or the thread has ended

    def ready(d: Any, s: Any) -> None:
        box.update(daemon=d, sim=s)
        started.set()

    def target() -> None:
        try:
            run_sim(scene, stop, ports.append, workdir=workdir, overrides=overrides, on_ready=ready)
        except BaseException as exc:  # reported to the starter
            errors.append(exc)
        finally:
            started.set()

    # The daemon logs each measurement at INFO; the user sees results on stdout instead.
    # (unless the caller configured that logger, e.g. ``thermotouch --verbose``).
    log = logging.getLogger("thermotouch")
    if log.level == logging.NOTSET:
        log.setLevel(logging.WARNING)
    th = threading.Thread(target=target, name="thermotouch-sim", daemon=True)
    th.start()
    started.wait(SIM_START_TIMEOUT_s)
    try:
        if "sim" not in box:
            why = f"{type(errors[0]).__name__}: {errors[0]}" if errors else "no answer"
            raise DeviceUnavailable(f"simulated probe on scene {scene} did not start: {why}")
        yield ports[0], box["daemon"], box["sim"]
    finally:
        stop.set()
        if "daemon" in box:
            box["daemon"].wake()  # no read timeout to wait out
        th.join(SIM_START_TIMEOUT_s)


@contextlib.contextmanager
def open_device(port: str | None = None, sim: str | None = None, *, workdir: str | Path | None = None,
                timeout_s: float = 3.0, overrides: dict | None = None) -> Iterator[DeviceSession]:
    """Open a probe on ``port``, or a simulated probe on scene ``sim`` for the duration.

    Raises
    ------
    DeviceUnavailable
        For every problem a user can meet (see the module docstring); client
        errors raised inside the block are converted too.
    """
    if (port is None) == (sim is None):
        raise DeviceUnavailable("give exactly one of --port PORT or --sim SCENE", 2)
    if sim is not None:
        with simulated_probe(sim, workdir, overrides=overrides) as (host_port, daemon, simulator):
            with device_errors(host_port):
                client = DeviceClient(host_port, timeout_s=timeout_s)
            with client, device_errors(f"simulated probe ({sim})"):
                yield DeviceSession(client, host_port, daemon, simulator,
                                    Path(workdir) if workdir is not None else None)
        return
    with device_errors(port):
        client = DeviceClient(port, timeout_s=timeout_s)
    with client, device_errors(port):
        yield DeviceSession(client, port)
