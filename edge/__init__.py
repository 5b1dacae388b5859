"""ThermoTouch edge: everything that runs on the probe (NumPy only at run time).

:mod:`edge.status` is the shared vocabulary of a measurement record (status,
reason, quality flags); :mod:`edge.checks` the shared argument checks.
"""

__version__ = "0.1.0"
