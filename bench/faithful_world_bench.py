"""Wall time of a simulated touch on FaithfulWorld (firmware_sim/rz/probe_world.py).

One session as the chips see it: the probe in air for 1 s, then a 2-s touch
with the heater on from contact (the device switches it on through a drive
that only knows what was commanded so far), then the lift.  Virtual time
advances in 5-ms ticks; at every tick the thermocouple and the flux voltage
are read at "now" (as the MCP9600 / ADS1115 models do), so the world steps
with the clock, with provisional steps re-checked on every read.  The wall
time covers everything: world construction, both grid configurations (air,
contact), their factorisations (main step and start-up sub-steps), stepping
and read-outs.

Cases: glass, PMMA, aluminium (scene ``*_15V``, object 3 K colder than the
probe, R_c = 2e-4 m^2K/W), dt = 10 ms and 5 ms.  Reported: median and
min-max over ``--repeat`` runs; budget 2 s per session.

Run:  python bench/faithful_world_bench.py [--repeat 5]
Writes bench/results/faithful_world.json.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import sys
import time

from _common import ROOT, write_json

sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from firmware_sim.clock import VirtualClock  # noqa: E402
from firmware_sim.rz.probe_world import FaithfulWorld  # noqa: E402
from firmware_sim.scene.files import read_scene  # noqa: E402

PRE_S, TOUCH_S, TICK_S = 1.0, 2.0, 0.005
SCENES = {"glass": "glass_15V", "PMMA": "pmma_15V", "aluminium": "alu_15V"}


class LiveDrive:
    """Duty commanded so far (like the board's enable line and PWM history)."""

    def __init__(self) -> None:
        self.t: list[float] = []
        self.d: list[float] = []

    def set(self, t: float, duty: float) -> None:
        self.t.append(t)
        self.d.append(duty)

    def duty_at(self, t_s: float) -> float:
        i = int(np.searchsorted(self.t, t_s, side="right")) - 1
        return self.d[i] if i >= 0 else 0.0

    def change_times(self):
        return list(self.t)


def session(name: str, dt: float) -> dict:
    sc = read_scene(SCENES[name])
    sc = dataclasses.replace(
        sc, contact_resistance_m2K_W=2e-4,
        environment=dataclasses.replace(sc.environment, initial_temperature_C=22.0, ambient_temperature_C=25.0),
        touch=dataclasses.replace(sc.touch, start_s=PRE_S, length_s=TOUCH_S))
    t0 = time.perf_counter()
    clock, drive = VirtualClock(), LiveDrive()
    w = FaithfulWorld(sc, clock, drive, dt_s=dt)
    n = int(round((PRE_S + TOUCH_S) / TICK_S))
    T = q = 0.0
    for k in range(1, n + 1):
        now = clock.advance(TICK_S)
        if k == int(round(PRE_S / TICK_S)):
            drive.set(now, 1.0)          # the device switches the heater on at contact
        T = w.thermocouple_C(now)
        q = w.flux_voltage_V(now)
    drive.set(clock.now(), 0.0)
    w.thermocouple_C(clock.now())
    total = time.perf_counter() - t0
    led = w.energy_ledger(clock.now())
    return {"total_s": total, "steps": len(w._steps), "reads": 2 * n, "T_tc_end_C": T, "flux_V_end": q,
            "ledger_residual_rel": abs(led["residual"]) / led["e_in"],
            "factorisations": sum(len(c.solvers) for c in w._configs.values())}


def summary(runs: list[dict], key: str) -> dict:
    v = [r[key] for r in runs]
    return {"median": statistics.median(v), "min": min(v), "max": max(v)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    cases = {}
    for dt in (0.01, 0.005):
        for name in SCENES:
            session(name, dt)  # warm-up
            runs = [session(name, dt) for _ in range(args.repeat)]
            row = {"total_s": summary(runs, "total_s")}
            row.update({k: runs[-1][k] for k in ("steps", "reads", "factorisations", "T_tc_end_C", "flux_V_end",
                                                  "ledger_residual_rel")})
            cases[f"{name}/dt={dt * 1e3:g}ms"] = row
            t = row["total_s"]
            print(f"{name:9s} dt {dt * 1e3:4.1f} ms: 1 s air + 2 s touch {t['median'] * 1e3:6.0f} ms "
                  f"(min {t['min'] * 1e3:.0f}, max {t['max'] * 1e3:.0f}); {row['steps']} steps, "
                  f"{row['factorisations']} factorisations, {row['reads']} reads")
    worst = {f"{dt * 1e3:g}ms": max(c["total_s"]["median"] for k, c in cases.items() if k.endswith(f"={dt * 1e3:g}ms"))
             for dt in (0.01, 0.005)}
    print(f"worst median session: {worst} (budget 2 s)")
    path = write_json("faithful_world", {
        "what": "wall time of 1 s in air + a 2-s touch with the heater on, on FaithfulWorld, read at 5-ms ticks "
                "(world construction, grids, factorisations, stepping, read-outs), median and min-max over repeats",
        "command": "python bench/faithful_world_bench.py" + (f" --repeat {args.repeat}" if args.repeat != 5 else ""),
        "tick_s": TICK_S, "pre_contact_s": PRE_S, "touch_s": TOUCH_S, "repeat": args.repeat,
        "cases": cases, "worst_median_s": worst, "budget_s": 2.0,
    })
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
