"""Test rigs built from the simulator's parts (``daemon_rig``: a fast analytic rig for daemon tests)."""
