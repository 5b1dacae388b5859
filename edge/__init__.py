"""ThermoTouch edge: everything that runs on the probe (NumPy only at run time)."""

__version__ = "0.1.0"
