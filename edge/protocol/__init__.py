"""The serial protocol: framing, commands, messages and the device-side endpoint."""
