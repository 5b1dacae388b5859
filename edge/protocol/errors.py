"""Protocol error codes and the exceptions that carry them to an ERROR reply."""

from __future__ import annotations

import enum

class ErrorCode(enum.IntEnum):
    """Error codes carried by ERROR replies (sent on the wire by name)."""

    BAD_FRAME = 1         # CRC-valid frame that cannot be parsed (version, JSON, layout)
    UNKNOWN_COMMAND = 2   # msg_type is not a known request
    BAD_ARGUMENT = 3      # argument missing, of the wrong type or out of range
    BUSY = 4              # device busy (e.g. a measurement or upload is running)
    MODEL_REJECTED = 5    # model upload failed size/sha256/format checks
    SENSOR_FAULT = 6      # hardware fault during a measurement
    INTERNAL = 7          # unexpected device-side exception
    NOT_FOUND = 8         # e.g. RESULT for an unknown measurement id
    BAD_STATE = 9         # command not valid now (e.g. MODEL_CHUNK without MODEL_BEGIN)


class CommandError(Exception):
    """A command failed; the device answers with an ERROR reply.

    Device-side handlers raise this (e.g. ``CommandError(ErrorCode.BUSY,
    "measurement in progress")``) and the link turns it into an ERROR reply.

    Parameters
    ----------
    code : ErrorCode
        Machine-readable error class.
    message : str
        Human-readable explanation.
    field : str, optional
        Name of the offending argument, if any.
    """

    def __init__(self, code: ErrorCode, message: str, field: str | None = None) -> None:
        self.code = ErrorCode(code)
        self.message = str(message)
        self.field = field
        super().__init__(f"{self.code.name}: {self.message}" + (f" (field {field!r})" if field else ""))


class ProtocolError(CommandError, ValueError):
    """A message violates the protocol; ``field`` names the offending field.

    ``request_id`` is set when the error concerns a frame whose id is known,
    so an ERROR reply can be addressed to it.
    """

    def __init__(self, message: str, field: str | None = None,
                 code: ErrorCode = ErrorCode.BAD_ARGUMENT, request_id: int | None = None) -> None:
        super().__init__(code, message, field)
        self.request_id = request_id
