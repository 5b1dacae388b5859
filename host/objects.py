"""The user's object sets on a probe: upload (OBJECTS_BEGIN/CHUNK/COMMIT), list, remove, select.

The host checks a file with the device's own parser before sending it
(``host.cli.common.load_object_set``); the device checks it again, with its
size and sha256, before it stores anything (:mod:`edge.service.objects`).
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any, Callable

from edge.protocol.commands import Command
from edge.protocol.messages import SESSION_CHUNK_HEADER_SIZE

__all__ = ["set_name_of", "stamp_version", "upload_object_set", "list_object_sets", "remove_object_set",
           "select_object_set", "SEPARATION_SIGMAS", "board_noise", "attainable_u_ln_e", "inseparable_pairs"]


def set_name_of(path: str | Path) -> str:
    """The name a file's set is stored under by default: its stem (``kitchen.csv`` -> ``kitchen``)."""
    return Path(path).stem


def stamp_version(data: bytes) -> bytes:
    """``data`` with its version line (``# created_utc: now``) first, unless it names one already.

    A signed set must name its version (:mod:`edge.storage.objects_store`): a device refuses a signed
    set not newer than the newest it installed, so an old signed set cannot be replayed.
    """
    from datetime import datetime, timezone  # noqa: PLC0415

    from edge.storage.objects_store import set_created_utc  # noqa: PLC0415

    if set_created_utc(data) is not None:
        return data
    now = datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    return f"# created_utc: {now}\n".encode("ascii") + data.removeprefix(b"\xef\xbb\xbf")


def upload_object_set(client: Any, name: str, data: bytes, *, activate: bool = True, chunk_size: int | None = None,
                      progress: Callable[[int, int], None] | None = None, key: Any = None) -> dict:
    """Upload one object-set CSV in chunks and commit it.

    Parameters
    ----------
    client : host.client.DeviceClient
    name : str
        Name to store it under (a set of that name is replaced).
    data : bytes
        The CSV file's bytes.
    activate : bool
        Make it the set that names each measurement's object.
    chunk_size : int, optional
        Bytes per OBJECTS_CHUNK (default and maximum: what one frame holds).
    progress : callable, optional
        ``progress(bytes_sent, total)`` after each chunk.
    key : edge.security.keys.SecretKey, optional
        Sign the CSV bytes with it (the signature travels in
        OBJECTS_BEGIN), after :func:`stamp_version` names their version;
        without one the upload is unsigned, which a device refuses unless it
        allows unsigned updates.

    Returns
    -------
    dict
        The OBJECTS_COMMIT reply: ``name``, ``sha256``, ``objects``, ``active``.

    Raises
    ------
    host.client.DeviceError
        The device refused it (its message names line and column for a bad
        CSV); an upload cut short is aborted (best effort), and the device's
        sets are unchanged either way.
    """
    from host.client import BadReply, ClientError  # noqa: PLC0415

    data = bytes(data)
    if key is not None:
        data = stamp_version(data)
    digest = hashlib.sha256(data).hexdigest()
    max_chunk = client.max_payload - SESSION_CHUNK_HEADER_SIZE
    chunk_size = max_chunk if chunk_size is None else min(int(chunk_size), max_chunk)
    args = {"name": name, "size": len(data), "sha256": digest, "activate": bool(activate)}
    if key is not None:
        from edge.security.keys import signature_document  # noqa: PLC0415

        args["signature"] = signature_document(key, data).decode("utf-8")  # JSON text in a JSON request
    begin = client.request(Command.OBJECTS_BEGIN, args)
    session = begin["session"]
    try:
        for offset in range(0, len(data), chunk_size):
            chunk = data[offset:offset + chunk_size]
            reply = client.request(Command.OBJECTS_CHUNK, {"offset": offset, "data": chunk, "session": session})
            if reply["received"] != offset + len(chunk):
                raise BadReply(f"device holds {reply['received']} B after the chunk at {offset} "
                               f"(expected {offset + len(chunk)} B)")
            if progress is not None:
                progress(offset + len(chunk), len(data))
        result = client.request(Command.OBJECTS_COMMIT, {"session": session})
    except BaseException:
        try:
            client.request(Command.OBJECTS_ABORT, {"session": session}, retries=0)
        except ClientError:
            pass
        raise
    if result["sha256"] != digest:
        raise BadReply(f"device stored sha256 {result['sha256']}, expected {digest}")
    return result


def list_object_sets(client: Any) -> dict:
    """OBJECTS_LIST: ``{"active": name, "sets": [...], "error": str | None}``."""
    return client.request(Command.OBJECTS_LIST)


def remove_object_set(client: Any, name: str) -> dict:
    """OBJECTS_REMOVE: ``{"removed": name, "active": name}``."""
    return client.request(Command.OBJECTS_REMOVE, {"name": name})


def select_object_set(client: Any, name: str) -> dict:
    """OBJECTS_SELECT (``"library"``: the built-in set): ``{"active": name}``."""
    return client.request(Command.OBJECTS_SELECT, {"name": name})


#: A pair is reported when its objects' ln e differ by less than this many standard deviations of the
#: difference (as :meth:`edge.recognition.ObjectSet.confusion_pairs`): below 2, a touch of either is
#: named the other more than about one time in six.
SEPARATION_SIGMAS = 2.0


def board_noise(board: str = "precision") -> tuple[float, float, float]:
    """(sigma_T_K, sigma_q_W_m2, dt_s) of one sample of a board (:data:`edge.hw.chips.BOARDS`).

    From the chip registry's noise models of the chip playing each role (:meth:`edge.hw.chips.NoiseModel.reading_sd`:
    input-referred noise and the converter's step as uniform rounding); the sample interval is the
    device's default rate capped by the thermocouple converter's (50 Hz on the precision board,
    12.5 Hz on the reference board's MCP9600).
    """
    from edge.hw.chips import BOARDS, CHIPS, FLUX, THERMOCOUPLE  # noqa: PLC0415
    from edge.service.config import MeasurementConfig  # noqa: PLC0415

    if board not in BOARDS:
        raise ValueError(f"unknown board {board!r}; boards: {sorted(BOARDS)}")
    T, q = (CHIPS[BOARDS[board][role]].models[role] for role in (THERMOCOUPLE, FLUX))
    rate_Hz = min(float(MeasurementConfig().sample_rate_Hz), T.rate_Hz)
    return T.reading_sd(), q.reading_sd(), 1.0 / rate_Hz


def attainable_u_ln_e(objects: Any, contact_time_s: float, *, probe: str = "paper", board: str = "precision",
                      sigma_T_K: float | None = None, sigma_q_W_m2: float | None = None,
                      dt_s: float | None = None) -> dict[str, float]:
    """Each object's attainable u(e)/e at ``contact_time_s`` (Fisher bound, :func:`edge.estimation.design.attainable`).

    The hand touch's unknown contact resistance is among the fitted quantities (``fit_contact``):
    what a touch by hand can resolve at best, before calibration and specimen spread.  An object
    given by e alone is taken with the library's rho c prior (its alpha then follows from e).  Noise and
    sample interval: ``board``'s (:func:`board_noise`), unless given.
    """
    import math  # noqa: PLC0415

    import numpy as np  # noqa: PLC0415

    from edge.estimation.design import attainable  # noqa: PLC0415
    from edge.physics.axisym import AxisymModel  # noqa: PLC0415
    from edge.physics.geometry import PROBES  # noqa: PLC0415
    from edge.physics.solids import Solid  # noqa: PLC0415
    from host.recognition import library_estimator  # noqa: PLC0415

    bT, bq, bdt = board_noise(board)
    sigma_T_K = bT if sigma_T_K is None else sigma_T_K
    sigma_q_W_m2 = bq if sigma_q_W_m2 is None else sigma_q_W_m2
    dt = bdt if dt_s is None else dt_s
    t = dt * np.arange(1, int(math.floor(contact_time_s / dt + 1e-9)) + 1)
    model = AxisymModel(PROBES[probe], t)   # its probe part is the costly setup: once for every object
    lib = None
    out = {}
    for o in objects.objects:
        if o.has_properties:
            solid = Solid(k_W_mK=o.k_W_mK, rho_kg_m3=o.rho_kg_m3, c_J_kgK=o.c_J_kgK)
        else:
            lib = lib or library_estimator().library
            rho_c = math.exp(lib.prior_rho_c(o.e_W_s05_m2K, 0.0)[0])
            solid = Solid(k_W_mK=o.e_W_s05_m2K ** 2 / rho_c, rho_kg_m3=rho_c / 1000.0, c_J_kgK=1000.0)
        d = attainable(solid, contact_time_s, probe=probe, dt_s=dt, sigma_T_K=sigma_T_K, sigma_q_W_m2=sigma_q_W_m2,
                       fit_contact=True, model=model)
        out[o.name] = float(d.u_rel_effusivity)
    return out


def inseparable_pairs(objects: Any, u_ln_e: dict[str, float]) -> list[dict]:
    """Pairs whose ln e differ by less than :data:`SEPARATION_SIGMAS` sd of the difference, closest first.

    The difference's variance: both objects' ``u_ln_e`` (per object: :func:`attainable_u_ln_e`),
    their specimen spreads and twice the set's ``calibration_ln``.
    """
    import math  # noqa: PLC0415

    names, ln_e, spread = objects.names, objects.ln_e, objects.spread
    out = []
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            var = (u_ln_e[names[i]] ** 2 + u_ln_e[names[j]] ** 2 + spread[i] ** 2 + spread[j] ** 2
                   + 2 * objects.calibration_ln ** 2)
            d = abs(float(ln_e[i] - ln_e[j]))
            thr = SEPARATION_SIGMAS * math.sqrt(var)
            if d < thr:
                a, b = (i, j) if ln_e[i] <= ln_e[j] else (j, i)
                out.append({"a": names[a], "b": names[b], "delta_ln_e": d, "threshold_ln": thr,
                            "u_a": u_ln_e[names[a]], "u_b": u_ln_e[names[b]]})
    return sorted(out, key=lambda p: p["delta_ln_e"] / p["threshold_ln"])
