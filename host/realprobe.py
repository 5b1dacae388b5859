"""The real-probe demonstration: calibrate an as-built probe on reference materials, then measure.

``thermotouch demo --real-probe`` runs this on the simulator's faithful world
(the (r, z) finite-volume probe, never the estimator's model), precision
board, one as-built probe (its thermopile 4 % more sensitive than the
datasheet, its sensing layer 5 % thicker and 4 % less conductive, a 60-ms
bead -- never told to the device):

1. the probe touches three reference specimens (pmma, pyroceram, aisi_304),
   each a little off the room's temperature with a dry contact, is recorded
   from the air before contact, and the host fits the calibration from the
   device's raw records (SERIES) with the device's own code
   (:func:`edge.calibration.fit.fit_calibration`), then installs it
   (CALIBRATION_SET);
2. the same probe touches the paper's nine (tempered glass, PMMA and aluminium
   alloy at the paper's three voltages each) with a contact resistance and an
   object warmer or colder than the probe, and each answer is printed: the
   default method's e, the sensor chain's e +- u with the datasheet chain
   (recomputed on the host from the same raw record) and with the installed
   calibration (the device's), against the truth.

Every touch is one MEASURE on a scene written to the work directory (the
same ``[as_built]`` in each), all sharing one daemon work directory, so the
calibration installed after step 1 is the one step 2's measurements use.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

__all__ = ["AS_BUILT", "REFERENCE_TOUCHES", "TEST_TOUCHES", "calibrate_probe", "measure_nine", "run_real_probe"]

#: The demonstration's probe as built ([as_built] of every scene).
AS_BUILT = {"sensing_thickness_factor": 1.05, "sensing_k_factor": 0.96, "flux_sensitivity_factor": 1.04,
            "thermocouple_time_constant_s": 0.06, "heater_tcr_per_K": 1.0e-4, "heater_reference_C": 25.0}
#: Heating time of every touch (s): long enough for a metal's rise to stand out of the noise.
HEAT_s = 8.0


@dataclass(frozen=True)
class Touch:
    material: str
    contact_resistance_m2K_W: float
    object_offset_K: float
    lead_s: float
    voltage_V: float


REFERENCE_TOUCHES = (Touch("pmma", 1e-5, -1.0, 1.0, 12.0), Touch("pyroceram", 1e-5, 1.0, 1.0, 15.0),
                     Touch("aisi_304", 1e-5, 1.0, 1.0, 20.0))
#: The paper's nine (Table 2: glass 12/15/18 V, PMMA 8/15/20 V, aluminium 15/20/25 V), each touched as
#: a hand does: a dry contact and an object off the probe's temperature, resting before the heating.
TEST_TOUCHES = (Touch("tempered_glass", 3e-5, -1.5, 2.0, 12.0), Touch("tempered_glass", 1e-5, 1.0, 1.0, 15.0),
                Touch("tempered_glass", 2e-5, 2.0, 3.0, 18.0), Touch("pmma", 2e-5, 2.0, 1.5, 8.0),
                Touch("pmma", 3e-5, -1.0, 2.0, 15.0), Touch("pmma", 1e-5, -2.0, 1.0, 20.0),
                Touch("aluminium_alloy", 2e-5, -1.0, 1.0, 15.0), Touch("aluminium_alloy", 1e-5, 1.5, 2.0, 20.0),
                Touch("aluminium_alloy", 3e-5, -2.0, 1.5, 25.0))


def scene_text(name: str, touch: Touch, seed: int) -> str:
    """A faithful-world, precision-board scene of one touch by the demonstration's as-built probe."""
    as_built = "\n".join(f"{k} = {v!r}" for k, v in AS_BUILT.items())
    return f"""name = "{name}"
description = "real-probe demo: {touch.material}, R_c {touch.contact_resistance_m2K_W:g}, object {touch.object_offset_K:+g} K"
seed = {seed}

[object]
material = "{touch.material}"
thickness_m = 0.05
back = "insulated"

[environment]
initial_temperature_C = 25.0
ambient_temperature_C = 25.0

[heater]
supply_voltage_V = {touch.voltage_V!r}
resistance_ohm = 50.0

[board]
ads122c04 = 0x40
mcp9600 = 0x60
stack = "0.42"
world = "faithful"
probe = "paper"

[sensors]
thermocouple_time_constant_s = 0.01
ads122c04_noise_rms_V = 0.15e-6
mcp9600_emf_noise_rms_V = 1.0e-6

[as_built]
{as_built}

[touch]
start_s = 1.0
length_s = {touch.lead_s + HEAT_s + 0.6!r}
contact_lead_s = {touch.lead_s!r}
contact_resistance_m2K_W = {touch.contact_resistance_m2K_W!r}
object_offset_K = {touch.object_offset_K!r}
press_trigger = false
"""


def _touch(out_dir: Path, workdir: Path, name: str, touch: Touch, seed: int, with_series: bool) -> dict[str, Any]:
    from host.device import open_device  # noqa: PLC0415

    path = out_dir / f"{name}.toml"
    path.write_text(scene_text(name, touch, seed), encoding="utf-8")
    with open_device(None, str(path), workdir=workdir, timeout_s=10.0) as session:
        rec = session.client.measure(contact_time_s=HEAT_s)
        series = session.client.series(rec["measurement_id"], "raw") if with_series else None
    return {"record": rec, "series": series}


def calibrate_probe(scenes: Path, workdir: Path, *, say: Callable[[str], None] = print):
    """Touch the three references with the demonstration probe, fit its calibration and install it.

    Returns the :class:`edge.calibration.model.ProbeCalibration`.
    """
    import numpy as np  # noqa: PLC0415

    from edge.calibration.fit import ReferenceTouch, fit_calibration  # noqa: PLC0415
    from edge.physics.materials import load_materials  # noqa: PLC0415
    from host.calibration import install_calibration  # noqa: PLC0415
    from host.device import open_device  # noqa: PLC0415

    lib = load_materials()
    refs = []
    for i, tc in enumerate(REFERENCE_TOUCHES):
        got = _touch(scenes, workdir, f"ref_{tc.material}", tc, 100 + i, with_series=True)
        s = got["series"]
        t, T, q = (np.asarray(s[k], float) for k in ("raw_t_s", "raw_T_C", "raw_q_W_m2"))
        keep = np.isfinite(t) & np.isfinite(T) & np.isfinite(q)
        refs.append(ReferenceTouch(tc.material, lib.get(tc.material).solid.effusivity_W_s05_m2K,
                                   t[keep], T[keep], q[keep]))
        say(f"reference {tc.material:<10} touched: {int(keep.sum())} samples, "
            f"{(got['record']['result'] or {}).get('sensor_chain', {}).get('contact_t_s', float('nan')):+.2f} s contact")
    cal = fit_calibration(refs, probe="paper")
    say(f"calibration {cal.sha256[:12]}: sensitivity x {1 / cal.chain.flux_scale:.3f}, depth "
        f"{cal.chain.sensing_thickness_m * 1e3:.3f} mm, layer k {cal.chain.k_W_mK:.3f}, lag "
        f"{cal.chain.tc_tau_s * 1e3:.0f} ms, floor {cal.u_rel_floor:.1%}")
    with open_device(None, str(scenes / f"ref_{REFERENCE_TOUCHES[0].material}.toml"), workdir=workdir,
                     timeout_s=10.0) as session:
        install_calibration(session.client, cal)
    return cal


def measure_nine(scenes: Path, workdir: Path, *, seed: int = 200, say: Callable[[str], None] | None = print,
                 ) -> list[dict[str, Any]]:
    """Touch the paper's nine (:data:`TEST_TOUCHES`) with the device's installed calibration.

    Scene i's noise is seeded ``seed + i``.  One row per touch: the default method's e, the
    datasheet chain's (recomputed on the host from the raw record) and the device's calibrated chain.
    """
    import numpy as np  # noqa: PLC0415

    from edge.estimation.chain_estimate import estimate_from_contact  # noqa: PLC0415
    from edge.physics.materials import load_materials  # noqa: PLC0415

    lib = load_materials()
    rows = []
    for i, tc in enumerate(TEST_TOUCHES):
        got = _touch(scenes, workdir, f"test_{i}_{tc.material}", tc, seed + i, with_series=True)
        rec, s = got["record"], got["series"]
        t, T, q = (np.asarray(s[k], float) for k in ("raw_t_s", "raw_T_C", "raw_q_W_m2"))
        keep = np.isfinite(t) & np.isfinite(T) & np.isfinite(q)
        try:  # the datasheet chain on the same record (what the probe said before its calibration)
            nominal = estimate_from_contact(t[keep], T[keep], q[keep], None)
        except ValueError as exc:
            nominal = {"error": str(exc)}
        e_true = lib.get(tc.material).solid.effusivity_W_s05_m2K
        res = rec.get("result") or {}
        # A trusted calibrated chain is the device's answer; the default method's is kept beside it.
        row = {"object": tc.material, "voltage_V": tc.voltage_V, "e_true": e_true,
               "default": (res.get("default_method") or res).get("effusivity_W_s05_m2K"),
               "answer_method": res.get("method"), "answer": res.get("effusivity_W_s05_m2K"),
               "uncalibrated": nominal, "calibrated": (rec.get("result") or {}).get("sensor_chain", {}),
               "flags": rec.get("flags")}
        rows.append(row)
        if say is not None:
            d = row["default"]
            dtxt = f"{d / e_true - 1:+7.1%}" if d else "   -   "
            solid = lib.get(tc.material).solid
            say(f"{tc.material:<16} {tc.voltage_V:3.0f} {e_true:7.0f} | {dtxt:>8} | {_cell(row['uncalibrated'], e_true)} | "
                f"{_cell(row['calibrated'], e_true)} | {', '.join(row['calibrated'].get('flags') or []) or '-'}"
                f"{_alpha_cell(row['calibrated'], solid.k_W_mK / solid.rho_c_J_m3K)}")
    return rows


def _cell(c: dict, e_true: float) -> str:
    e, u = c.get("effusivity_W_s05_m2K"), c.get("effusivity_W_s05_m2K_u")
    if e is None or u is None:
        return f"{'refused':>19}"
    return f"{e:7.0f} ± {u:4.0f} {e / e_true - 1:+6.1%}"


def _alpha_cell(c: dict, alpha_true: float) -> str:
    """The object's alpha where the touch measured it (a metal: its heat reaches the heater's edge)."""
    a, u = c.get("alpha_m2_s"), c.get("alpha_m2_s_u")
    if "alpha" not in (c.get("determined") or ()) or a is None or u is None:
        return ""
    return f"; alpha measured {a * 1e6:.0f} ± {u * 1e6:.0f} mm²/s ({a / alpha_true - 1:+.0%})"


def run_real_probe(out_dir: str | Path, *, say: Callable[[str], None] = print) -> dict[str, Any]:
    """Calibrate the demonstration probe, install the calibration, measure the paper's materials.

    Returns the calibration (its dict) and one row per test touch.
    """
    import numpy as np  # noqa: PLC0415

    out = Path(out_dir)
    scenes, workdir = out / "scenes", out / "probe"
    scenes.mkdir(parents=True, exist_ok=True)
    workdir.mkdir(parents=True, exist_ok=True)
    say(f"as-built probe (never told to the device): {', '.join(f'{k} {v:g}' for k, v in AS_BUILT.items())}")
    cal = calibrate_probe(scenes, workdir, say=say)
    say("")
    say(f"{'object':<16} {'V':>3} {'true e':>7} | {'default':>8} | {'chain, datasheet':>19} | "
        f"{'chain, calibrated':>19} | flags")
    rows = measure_nine(scenes, workdir, say=say)
    errs = [abs((r["calibrated"].get("effusivity_W_s05_m2K") or math.inf) / r["e_true"] - 1) for r in rows]
    say(f"\ncalibrated sensor chain: {sum(x <= 0.03 for x in errs)} of {len(errs)} within 3 %, "
        f"median |error| {float(np.median(errs)):.1%}; the device answered with it on "
        f"{sum(r['answer_method'] == 'sensor_chain' for r in rows)} of {len(rows)} (the default method's e in "
        f"result.default_method)")
    return {"calibration": cal.to_dict(), "sha256": cal.sha256, "rows": rows, "abs_errors": errs}
