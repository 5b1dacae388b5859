"""Register-level emulations of the board's I2C chips.

One module per chip: ``MCP9600Emulator``, ``ADS1115Emulator``,
``ADS122C04Emulator``. Each takes its register map and datasheet constants
from :mod:`edge.hw.regmaps` -- the same data the edge drivers use -- and
never from a driver. :mod:`firmware_sim.chips.registry` registers each
against its entry in the chip registry (:data:`edge.hw.chips.CHIPS`); the
simulator builds every fitted chip from there, on the inputs the wiring table
(:mod:`firmware_sim.wiring`) gives it. ``tests/firmware_sim/test_chip_contract.py``
runs one contract over every registry chip's driver/emulator pair.
"""
