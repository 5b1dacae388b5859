"""A long simulated session: does the thermal world's cost per touch stay flat?

N touches (default 1000) on one scene, driven directly -- the thermal world,
the MCP9600 (18 bit) and ADS1115 (860 SPS continuous) models on a virtual
clock and a :class:`firmware_sim.world.ManualDrive` for the heater, no board,
bus or drivers, so what is timed is the world and the chips. Each touch:
2.5 s of contact with 2 s of full-duty heating, both chips read every 10 ms
of virtual time, then 5 s in air (the chips catch up at the next touch).

Reported (bench/results/sim_session.json): wall time per touch, median and
min-max, over the first 100 and the last 100 touches (and their ratio);
Talbot calls and rows (terms x times) per touch over the same windows; the
most terms superposed at one time; the retained state (phases recorded,
cached states); the process's resident memory after the first 100 touches
and at the end, and its peak (ru_maxrss).

Run:  python bench/sim_session_bench.py [--n 1000] [--scene glass_15V]
"""

from __future__ import annotations

import argparse
import resource
import statistics
import sys
import time
from pathlib import Path

from _common import ROOT, write_json

sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from firmware_sim.chips.ads1115 import ADS1115Emulator as ADS1115Model  # noqa: E402
from firmware_sim.chips.mcp9600 import MCP9600Emulator as MCP9600Model  # noqa: E402
from firmware_sim.clock import VirtualClock  # noqa: E402
from firmware_sim.scene.files import read_scene  # noqa: E402
from firmware_sim.wiring import connect  # noqa: E402
from firmware_sim.world import ManualDrive, ThermalWorld  # noqa: E402

TOUCH_S, HEAT_S, AIR_S, READ_DT_S = 2.5, 2.0, 5.0, 0.01
WINDOW = 100


def _rss_MB() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def _spread(values: list[float]) -> dict:
    return {"median": statistics.median(values), "min": min(values), "max": max(values),
            "mean": statistics.fmean(values)}


def run(n: int, scene_name: str) -> dict:
    sc = read_scene(scene_name)
    clock = VirtualClock()
    drive = ManualDrive()
    world = ThermalWorld(sc, clock, drive)
    seeds = np.random.SeedSequence(sc.seed).spawn(2)
    mcp = MCP9600Model(clock, world.thermocouple_C, world.cold_junction_C, rng=np.random.default_rng(seeds[0]),
                       emf_noise_rms_V=sc.sensors.mcp9600_emf_noise_rms_V, open_circuit=world.thermocouple_open)
    ads = ADS1115Model(clock, connect(world, "ads1115").mux, noise_rms_V=sc.sensors.ads1115_noise_rms_V,
                       rng=np.random.default_rng(seeds[1]))
    ads.i2c_write(bytes([0x01, 0x0A, 0xE3]))   # AIN0-AIN1, +-0.256 V, continuous, 860 SPS, comparator off
    ads.i2c_write(bytes([0x00]))               # pointer: conversion register
    per_touch: list[dict] = []
    rss_after_window = None
    t0 = sc.touch.start_s
    for i in range(n):
        w0 = time.perf_counter()
        before = dict(world.stats)
        if i:
            world.add_touch(t0, TOUCH_S)
        clock.advance_to(t0)
        drive.set(t0, 1.0)
        steps = int(round(HEAT_S / READ_DT_S))
        for _ in range(steps):
            clock.advance(READ_DT_S)
            mcp.i2c_write(bytes([0x00]))
            mcp.i2c_read(2)
            ads.i2c_read(2)
        drive.set(clock.now(), 0.0)
        clock.advance_to(t0 + TOUCH_S + AIR_S)
        wall = time.perf_counter() - w0
        per_touch.append({"wall_s": wall, **{k: world.stats[k] - before[k] for k in
                                               ("talbot_calls", "talbot_rows", "times", "queries")}})
        t0 = clock.now()
        if i + 1 == min(WINDOW, n):
            rss_after_window = _rss_MB()
    first, last = per_touch[:WINDOW], per_touch[-WINDOW:]

    def window(rows):
        return {"wall_s_per_touch": _spread([r["wall_s"] for r in rows]),
                "talbot_calls_per_touch": _spread([r["talbot_calls"] for r in rows]),
                "talbot_rows_per_touch": _spread([r["talbot_rows"] for r in rows]),
                "queries_per_touch": _spread([r["queries"] for r in rows])}

    return {
        "first": window(first), "last": window(last),
        "last_over_first_median_wall": (statistics.median([r["wall_s"] for r in last])
                                        / statistics.median([r["wall_s"] for r in first])),
        "max_terms_at_one_time": world.stats["max_terms"],
        "retained": {"phases_recorded": len(world.phases()), "cached_states": len(world._cache),
                     "lookahead_values": sum(s.n for s in world._streams.values())},
        "rss_MB": {"after_first_100": rss_after_window, "end": _rss_MB(),
                   "peak": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0},
        "virtual_time_s": clock.now(),
        "per_touch_wall_s": [r["wall_s"] for r in per_touch],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1000, help="touches (default 1000)")
    ap.add_argument("--scene", default="glass_15V")
    args = ap.parse_args()
    if args.n < 2 * WINDOW:
        ap.error(f"--n must be >= {2 * WINDOW}")
    t0 = time.perf_counter()
    res = run(args.n, args.scene)
    res.pop("per_touch_wall_s")  # the scaling bench bins it; this report keeps the windows
    total = time.perf_counter() - t0
    f, l = res["first"], res["last"]
    print(f"{args.n} touches on {args.scene} in {total:.1f} s wall ({res['virtual_time_s']:.0f} s virtual)")
    for name, w in (("first", f), ("last", l)):
        print(f"  {name} {WINDOW}: {w['wall_s_per_touch']['median'] * 1e3:.1f} ms/touch "
              f"({w['wall_s_per_touch']['min'] * 1e3:.1f}-{w['wall_s_per_touch']['max'] * 1e3:.1f}), "
              f"{w['talbot_calls_per_touch']['mean']:.1f} Talbot calls, "
              f"{w['talbot_rows_per_touch']['mean']:.0f} rows, {w['queries_per_touch']['mean']:.0f} values per touch")
    print(f"  last/first median: {res['last_over_first_median_wall']:.2f}; most terms at one time "
          f"{res['max_terms_at_one_time']}; retained {res['retained']}")
    print(f"  RSS after {WINDOW}: {res['rss_MB']['after_first_100']:.1f} MB, end {res['rss_MB']['end']:.1f} MB, "
          f"peak {res['rss_MB']['peak']:.1f} MB")
    path = write_json("sim_session", {
        "what": "a session of N touches on the thermal world + MCP9600/ADS1115 models (no board, bus or "
                "drivers): wall time and work per touch over the first and last 100 touches, memory",
        "command": "python bench/sim_session_bench.py" + (f" --n {args.n}" if args.n != 1000 else "")
                   + (f" --scene {args.scene}" if args.scene != "glass_15V" else ""),
        "n_touches": args.n, "scene": args.scene, "wall_s_total": total,
        "touch": {"contact_s": TOUCH_S, "heating_s": HEAT_S, "air_s": AIR_S, "read_every_s": READ_DT_S},
        **res,
    })
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
