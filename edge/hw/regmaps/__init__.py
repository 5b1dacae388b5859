"""Chip register maps and datasheet constants as pure data, shared by the drivers and the emulators."""
