"""A touch: sensors, the measurement sequence and the heater's safety net, instrument models, profiles."""
