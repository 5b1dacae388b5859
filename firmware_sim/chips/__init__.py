"""Register-level emulations of the board's I2C chips.

One module per chip: ``MCP9600Emulator``, ``ADS1115Emulator``,
``ADS122C04Emulator``. Each takes its register map and datasheet constants
from :mod:`edge.hw.regmaps` -- the same data the edge drivers use -- and
never from a driver. ``tests/firmware_sim/test_chip_contract.py`` runs one
contract over every driver/emulator pair.
"""
