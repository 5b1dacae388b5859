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
           "select_object_set"]


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
