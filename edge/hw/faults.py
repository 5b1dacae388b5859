"""Sensor faults raised by the edge drivers.

One exception type for every way a sensor can fail, so the daemon can catch a
single class and still report *which* sensor failed and *why*.
"""

from __future__ import annotations

#: Reasons the drivers use; other modules may add their own strings.
KNOWN_REASONS = (
    "i2c",                # bus error (NACK, EREMOTEIO, EIO...) after all retries
    "timeout",            # bus timed out (ETIMEDOUT) or a conversion never finished
    "not_found",          # chip answered with an unexpected identity
    "open_thermocouple",  # MCP9600 reports its input out of range (open circuit)
    "saturated",          # ADC code at full scale: the input is clipped
    "crc",                # data-integrity check failed (ADS122C04 CRC / inverted data)
)


class SensorFault(RuntimeError):
    """A sensor could not deliver a valid reading.

    Parameters
    ----------
    sensor : str
        Which sensor, conventionally ``"<chip>@0x<address>"``, e.g. ``"mcp9600@0x60"``.
    reason : str
        Short machine-readable cause, e.g. ``"i2c"``, ``"open_thermocouple"``,
        ``"saturated"``, ``"timeout"`` (see :data:`KNOWN_REASONS`).
    detail : str, optional
        Human-readable detail appended to the message.
    """

    def __init__(self, sensor: str, reason: str, detail: str = "") -> None:
        if not sensor:
            raise ValueError("sensor must be a non-empty string")
        if not reason:
            raise ValueError("reason must be a non-empty string")
        self.sensor = sensor
        self.reason = reason
        self.detail = detail
        msg = f"{sensor}: {reason}"
        if detail:
            msg += f" ({detail})"
        super().__init__(msg)

    def __reduce__(self):  # keep sensor/reason when pickled across processes
        return (type(self), (self.sensor, self.reason, self.detail))
