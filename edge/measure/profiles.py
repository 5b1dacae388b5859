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
from typing import Any

from edge.hw.chips import sample_rate_Hz


@dataclass(frozen=True)
class Profile:
    name: str
    contact_time_s: float
    summary: str
    #: Sampling rate the profile asks for (Hz), or None: the configured ``[measurement] sample_rate_Hz``
    #: (50 Hz by default: the one source of the paper probe's rate, so a profile that does not need
    #: another one never restates it). The device caps either at what its converters deliver
    #: (edge.hw.chips.max_sample_rate_Hz): the precision board (ADS122C04, two single-shot
    #: conversions of ~1 ms at 1000 SPS per sample) samples at 50 Hz, 25 samples in 0.5 s; the
    #: reference board's MCP9600 converts every 80 ms at 16 bit, so it stays at 12.5 Hz.
    sample_rate_Hz: float | None = None


PROFILES = {
    "quick": Profile("quick", 0.5, "0.5 s touch at 50 Hz: polymers, glasses and woods on the precision board",
                     sample_rate_Hz=50.0),
    "standard": Profile("standard", 2.0, "2 s touch, the paper's: every class on the precision board"),
    "precise": Profile("precise", 4.0, "4 s touch: metals on the reference board, ~0.1 % e on the precision one"),
}


#: The profile a probe head needs when nothing else is asked (``[board] probe``). The paper's probe
#: keeps the configured ``[measurement]`` settings. The small-heater probe resolves k and alpha only
#: from the record's departure from the 1-D shape, which grows with the heat's reach sqrt(alpha t)
#: against the 5-mm heater radius: its design (``thermotouch design --table``, README "Speed and
#: accuracy by probe") assumes 20-ms samples and reaches a few per cent on k and alpha at 5 s, while
#: 1 s leaves alpha at 32-81 % on every class. 20 samples of a 2-s touch at 10 Hz (a configured
#: rate below the default) do not resolve alpha even in the bound, so it asks 50 Hz itself.
PROBE_PROFILES = {
    "small-heater": Profile("small-heater", 5.0, "5 s touch at 50 Hz: k and alpha of the small-heater probe",
                            sample_rate_Hz=50.0),
}


def probe_profile(probe: str) -> Profile | None:
    """The profile the probe head needs, or None when the configured settings serve (the paper's probe).

    Parameters
    ----------
    probe : str
        A name in :data:`edge.physics.geometry.PROBES`.
    """
    return PROBE_PROFILES.get(probe)


def probe_settings(probe: str, sensors: Any, longest_contact_s: float | None = None) -> dict[str, float] | None:
    """``[measurement]`` contact time and sample rate for a probe head on the fitted converters.

    Parameters
    ----------
    probe : str
        The probe head (``[board] probe``).
    sensors : namespace
        The ``[sensors]`` section; the rate is capped at what its converters deliver
        (:func:`edge.hw.chips.max_sample_rate_Hz`), since faster reads would only
        repeat a conversion.
    longest_contact_s : float, optional
        The longest heating the touch allows (e.g. a simulated scene's contact); the profile's
        contact time is cut to it.

    Returns
    -------
    dict or None
        ``{"contact_time_s": ..., "sample_rate_Hz": ...}`` (no rate when the profile keeps the configured
        one), or None for a probe without its own profile.
    """
    prof = probe_profile(probe)
    if prof is None:
        return None
    contact = prof.contact_time_s if longest_contact_s is None else min(prof.contact_time_s, longest_contact_s)
    rate = prof.sample_rate_Hz
    out = {"contact_time_s": contact}
    if rate is not None:
        out["sample_rate_Hz"] = sample_rate_Hz(sensors, rate)
    return out
