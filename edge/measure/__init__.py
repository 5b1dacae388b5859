"""A touch: sensors, signal conditioning, the heater's watchdog, the measurement sequence,
instrument models, profiles."""
