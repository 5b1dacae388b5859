"""Measurement profiles: the contact-time trade users make.

A profile is a contact (heating) time; the power stays the device's
configured one (``heater.power_W``), since more power only ever helps up to
the heater's limit.  Their accuracy is not promised here but measured:
``python bench/estimation_bench.py`` reports the effusivity RMS error and the
stated uncertainty against contact time for both boards (README, "Estimation"),
and that table is the accuracy each profile states.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Profile:
    name: str
    contact_time_s: float
    summary: str


PROFILES = {
    "quick": Profile("quick", 0.5, "0.5 s touch: polymers, glasses and woods on the precision board"),
    "standard": Profile("standard", 2.0, "2 s touch, the paper's: every class on the precision board"),
    "precise": Profile("precise", 4.0, "4 s touch: metals on the reference board, ~0.1 % e on the precision one"),
}
