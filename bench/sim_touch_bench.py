"""Wall time of one simulated 2-s touch on the hardware-in-the-loop simulator.

For each of the paper's nine scenes: load the scene, build the sim board,
start the edge drivers (Heater, MCP9600 at 18 bit, ADS1115 continuous at
860 SPS), heat at full duty for 2 s of virtual time from the touch start and
read both chips every ``--dt`` seconds, then switch the heater off. The wall
time of the whole sequence (best of ``--repeat``) is what a HIL test pays per
touch. Also reported: the time spent in the thermal world (exact Laplace
evaluations) and how many evaluations the chips asked for.

Run:  python bench/sim_touch_bench.py [--dt 0.01] [--repeat 3]
Writes bench/results/sim_touch.json.
"""

from __future__ import annotations

import argparse
import sys
import time

from _common import ROOT, write_json

sys.path.insert(0, str(ROOT))  # the repo's firmware_sim package, also when run from bench/

import firmware_sim  # noqa: E402
from edge.hw.drivers.ads1115 import ADS1115  # noqa: E402
from edge.hw.drivers.heater import Heater  # noqa: E402
from edge.hw.drivers.mcp9600 import MCP9600  # noqa: E402

SCENES = ["glass_12V", "glass_15V", "glass_18V", "pmma_8V", "pmma_15V", "pmma_20V",
          "alu_15V", "alu_20V", "alu_25V"]


def one_touch(name: str, dt: float) -> dict:
    t0 = time.perf_counter()
    sim = firmware_sim.load_scene(name)
    sc = sim.scene
    world_time = [0.0]
    evals = [0]
    state = sim.world.state

    def timed_state(t):
        w0 = time.perf_counter()
        try:
            return state(t)
        finally:
            world_time[0] += time.perf_counter() - w0
            evals[0] += 1

    sim.world.state = timed_state
    board = sim.board()
    clk = board.clock
    heater = Heater(board, supply_voltage_V=sc.heater.supply_voltage_V, resistance_ohm=sc.heater.resistance_ohm)
    mcp = MCP9600(board.i2c, sc.board.mcp9600, sleep=clk.sleep)
    mcp.configure(adc_resolution_bits=18)
    ads = ADS1115(board.i2c, sc.board.ads1115, sleep=clk.sleep)
    ads.configure(fsr_V=0.256, data_rate_sps=860, mode="continuous")
    sim.advance_to(sc.touch.start_s)
    reads = 0
    with heater:
        heater.on(1.0)
        t_on = clk.monotonic()
        while clk.monotonic() < t_on + 2.0 - 1e-9:
            clk.sleep(dt)
            mcp.read_hot_junction_C()
            ads.read_latest_V()
            reads += 2
    wall = time.perf_counter() - t0
    sim.close()
    return {"wall_s": wall, "world_s": world_time[0], "world_evaluations": evals[0], "driver_reads": reads}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dt", type=float, default=0.01, help="read interval (virtual s)")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    rows = {}
    for name in SCENES:
        runs = [one_touch(name, args.dt) for _ in range(args.repeat)]
        best = min(runs, key=lambda r: r["wall_s"])
        rows[name] = best
        print(f"{name:10s} wall {best['wall_s'] * 1e3:7.1f} ms  world {best['world_s'] * 1e3:6.1f} ms "
              f"({best['world_evaluations']} evaluations)  {best['driver_reads']} driver reads")
    walls = [r["wall_s"] for r in rows.values()]
    summary = {"max_wall_s": max(walls), "median_wall_s": sorted(walls)[len(walls) // 2]}
    print(f"one simulated 2-s touch: median {summary['median_wall_s'] * 1e3:.0f} ms, "
          f"max {summary['max_wall_s'] * 1e3:.0f} ms wall")
    path = write_json("sim_touch", {
        "what": "wall time of one simulated 2-s touch (scene load + drivers + 2 s heating, "
                "MCP9600 18-bit and ADS1115 860 SPS read every dt)",
        "command": "python bench/sim_touch_bench.py" + (f" --dt {args.dt}" if args.dt != 0.01 else ""),
        "dt_s": args.dt, "repeat": args.repeat, "scenes": rows, "summary": summary,
    })
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
