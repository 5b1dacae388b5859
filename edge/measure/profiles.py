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
    #: Sampling rate the profile asks for (Hz); the device caps it at what its converters deliver
    #: (edge.service.requests.max_sample_rate_Hz): the precision board (ADS122C04, two single-shot
    #: conversions of ~1 ms at 1000 SPS per sample) samples the quick profile at 50 Hz, 25 samples in
    #: 0.5 s; the reference board's MCP9600 converts every 80 ms at 16 bit, so it stays at 12.5 Hz.
    sample_rate_Hz: float = 10.0


PROFILES = {
    "quick": Profile("quick", 0.5, "0.5 s touch at 50 Hz: polymers, glasses and woods on the precision board",
                     sample_rate_Hz=50.0),
    "standard": Profile("standard", 2.0, "2 s touch, the paper's: every class on the precision board"),
    "precise": Profile("precise", 4.0, "4 s touch: metals on the reference board, ~0.1 % e on the precision one"),
}
