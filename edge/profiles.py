"""Measurement profiles: the contact-time / power trade users make.

Each profile is a contact time and a heater power density.  Their accuracy
is not promised here but measured: ``python bench/estimation_bench.py``
reports effusivity RMS error and stated uncertainty against contact time for
both boards (README, "Estimation accuracy"), and the table there is the
accuracy each profile states.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Profile:
    name: str
    contact_time_s: float
    q_v_W_m3: float
    summary: str


PROFILES = {
    "quick": Profile("quick", 0.5, 1.2e8, "0.5 s touch: polymers, glasses and woods; not metals on the MCP9600 board"),
    "standard": Profile("standard", 2.0, 1.0e8, "2 s touch, the paper's: every class on the ADS122C04 board"),
    "precise": Profile("precise", 4.0, 1.0e8, "4 s touch: halves the effusivity error on metals"),
}
