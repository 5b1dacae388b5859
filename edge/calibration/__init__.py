"""Calibration of the probe on reference materials (ISSUE #10 §4): the model, the fit and the store.

Submodules are imported where used (nothing here imports them), so the device loads only what it needs.
"""
