"""One touch on the faithful world, recorded from before contact, as a device's converters would see it.

Used by the calibration bench and tests (ISSUE #10): the probe hangs in air,
touches an object at its own temperature ``lead_s`` before heater-on, heats
for ``heat_s`` and is recorded at ``dt_s`` from ``pre_s`` before contact.
The record is what the edge gets: the thermocouple through its true bead lag
and the thermopile voltage divided by the NOMINAL sensitivity, plus
Gaussian noise (the precision board's by default).  As-built deviations
(:class:`firmware_sim.rz.probe_world.AsBuilt`) are the probe's secret.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from edge.physics.solids import Solid

__all__ = ["ContactTouch", "record_touch", "one_d_geometry"]

#: Precision-board noise of one sample: thermocouple (K) and flux reading (W/m^2).
PRECISION_NOISE = (0.01, 0.5)



def _reference_steps() -> tuple[float, float]:
    """The reference board's converter steps (K, W/m^2) from the chip registry's instrument models.

    The MCP9600 at 16 bit (80-ms conversions, 12.5 Hz) resolves 8 uV of EMF, 0.197 K of type K: its
    register's 0.0625 K LSB only pays off at 18 bit (this table said 0.0625 K until issue #33's docs
    audit); the ADS1115's 7.8 uV LSB (PGA +-0.256 V) over the thermopile's 0.56 uV per W/m^2 is 14 W/m^2.
    """
    from edge.hw.chips import BOARDS as CHIP_BOARDS, CHIPS, FLUX, THERMOCOUPLE  # noqa: PLC0415

    chips = CHIP_BOARDS["reference"]
    return (CHIPS[chips[THERMOCOUPLE]].models[THERMOCOUPLE].lsb, CHIPS[chips[FLUX]].models[FLUX].lsb)


#: Per board: sample period (s), noise (K, W/m^2) and converter step (K, W/m^2; 0: none).  The
#: reference board's MCP9600 converts at 12.5 Hz; its EMF noise of 1 uV is 0.025 K of type K
#: (40.7 uV/K), the ADS1115's 2 uV noise over the thermopile's 0.56 uV per W/m^2 3.6 W/m^2 (the shipped
#: scenes' [noise] values); the steps are the registry's (:func:`_reference_steps`).
BOARDS = {
    "precision": (0.05, PRECISION_NOISE, (0.0, 0.0)),
    "reference": (0.08, (0.025, 3.6), _reference_steps()),
}


@dataclass(frozen=True)
class ContactTouch:
    """The conditions of one touch (everything the device does not know)."""

    solid: Solid
    contact_resistance_m2K_W: float = 0.0
    object_offset_K: float = 0.0       # object minus probe (the probe is at the room's temperature)
    lead_s: float = 1.0                # contact before heater-on
    heat_s: float = 2.0
    tail_s: float = 0.0                # recorded after the heater stops
    pre_s: float = 1.0                 # recorded in air before contact
    lift_s: float | None = None        # the probe leaves the object this long after heater-on


def one_d_geometry():
    """The world's 1-D limit (wide heater, no substrate, no convection): the chain's own geometry."""
    from firmware_sim.rz.grid import Mesh
    from firmware_sim.rz.probe_world import Geometry
    return Geometry(substrate=None, h_air_W_m2K=0.0, heater_radius_m=0.1, object_radius_m=0.15,
                    mesh=Mesh(max_dr_m=0.01))


def record_touch(touch: ContactTouch, *, as_built=None, geometry=None, scene_name: str = "glass_15V",
                 dt_s: float | None = None, world_dt_s: float = 0.05, noise=None, board: str = "precision",
                 seed: int | None = 0) -> dict[str, np.ndarray]:
    """Record one touch; returns ``t_s`` (0 at heater-on), ``T_C``, ``q_W_m2`` (the reading) and the truth.

    ``board`` (:data:`BOARDS`) sets the sample period, noise and converter steps unless ``dt_s`` /
    ``noise`` are given.  ``seed=None``: noise-free and unquantised.
    """
    if board not in BOARDS:
        raise ValueError(f"board must be one of {', '.join(BOARDS)}, got {board!r}")
    b_dt, b_noise, (lsb_T, lsb_q) = BOARDS[board]
    dt_s = b_dt if dt_s is None else dt_s
    noise = b_noise if noise is None else noise
    from firmware_sim.clock import VirtualClock
    from firmware_sim.rz.probe_world import AsBuilt, FaithfulWorld, geometry_for_probe
    from firmware_sim.scene.files import read_scene
    from firmware_sim.world import ScheduleDrive

    sc = read_scene(scene_name)
    env = sc.environment
    T_amb = env.ambient_temperature_C
    t_contact = 1.0 + touch.pre_s
    length = touch.lead_s + (touch.heat_s + touch.tail_s + 1.0 if touch.lift_s is None else touch.lift_s)
    sc = dataclasses.replace(
        sc, object=dataclasses.replace(sc.object, solid=touch.solid, back="infinite"),
        environment=dataclasses.replace(env, initial_temperature_C=T_amb + touch.object_offset_K),
        touch=dataclasses.replace(sc.touch, start_s=t_contact, length_s=length),
        contact_resistance_m2K_W=touch.contact_resistance_m2K_W)
    clk = VirtualClock()
    clk.advance(100.0)
    t_on = t_contact + touch.lead_s
    geo = geometry if geometry is not None else geometry_for_probe("paper")
    w = FaithfulWorld(sc, clk, ScheduleDrive([t_on, t_on + touch.heat_s], [1.0, 0.0]),
                      as_built=as_built if as_built is not None else AsBuilt(), geometry=geo, dt_s=world_dt_s)
    t_abs = np.arange(t_contact - touch.pre_s, t_on + touch.heat_s + touch.tail_s + 1e-9, dt_s)
    s = w.series(t_abs)
    q_read = s["q_sensor"] * (w.flux_sensitivity / sc.sensors.flux_sensitivity_V_per_W_m2)
    T = s["y"].copy()
    if seed is not None:
        rng = np.random.default_rng(seed)
        T = T + noise[0] * rng.standard_normal(T.size)
        q_read = q_read + noise[1] * rng.standard_normal(q_read.size)
        if lsb_T > 0:
            T = np.floor(T / lsb_T) * lsb_T      # the MCP9600 truncates to its step
        if lsb_q > 0:
            q_read = np.round(q_read / lsb_q) * lsb_q
    return {"t_s": t_abs - t_on, "T_C": T, "q_W_m2": q_read, "T_resolution_K": lsb_T if seed is not None else 0.0,
            "e_true": touch.solid.effusivity_W_s05_m2K,
            "T_probe0_C": T_amb, "T_obj0_C": T_amb + touch.object_offset_K,
            "contact_t_s": t_contact - t_on, "R_c": touch.contact_resistance_m2K_W}
