"""Wall time of one simulated 2-s touch on the hardware-in-the-loop simulator.

For each of the paper's nine scenes: load the scene, build the sim board,
start the edge drivers (Heater, MCP9600 at 18 bit, ADS1115 continuous at
860 SPS), heat at full duty for 2 s of virtual time from the touch start and
read both chips every ``--dt`` seconds, then switch the heater off. The wall
time of the whole sequence is what a HIL test pays per touch. The scenes are
run ``--repeat`` times interleaved (scene 1..9, then again), and each is
reported as the median with min-max over the repeats. Also reported: the
time spent in the thermal world (exact Laplace evaluations), how many values
the chips asked it for and how many Talbot inversion calls answered them.

Run:  python bench/sim_touch_bench.py [--dt 0.01] [--repeat 5]
Writes bench/results/sim_touch.json.
"""

from __future__ import annotations

import argparse
import statistics
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
    query = sim.world._query     # every value a chip asks for goes through here

    def timed_query(t, stream):
        w0 = time.perf_counter()
        try:
            return query(t, stream)
        finally:
            world_time[0] += time.perf_counter() - w0
            evals[0] += 1

    sim.world._query = timed_query
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
    talbot = sim.world.stats["talbot_calls"]
    sim.close()
    return {"wall_s": wall, "world_s": world_time[0], "world_evaluations": evals[0],
            "talbot_calls": talbot, "driver_reads": reads}


def _spread(values: list[float]) -> dict:
    return {"median": statistics.median(values), "min": min(values), "max": max(values)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dt", type=float, default=0.01, help="read interval (virtual s)")
    ap.add_argument("--repeat", type=int, default=5, help="interleaved repeats of the nine scenes")
    args = ap.parse_args()
    one_touch(SCENES[0], args.dt)   # warm-up (imports, first-call costs), not reported
    runs: dict[str, list[dict]] = {name: [] for name in SCENES}
    for _ in range(args.repeat):
        for name in SCENES:
            runs[name].append(one_touch(name, args.dt))
    rows = {}
    for name, rs in runs.items():
        rows[name] = {"wall_s": _spread([r["wall_s"] for r in rs]), "world_s": _spread([r["world_s"] for r in rs]),
                      "world_evaluations": rs[-1]["world_evaluations"], "talbot_calls": rs[-1]["talbot_calls"],
                      "driver_reads": rs[-1]["driver_reads"]}
        r = rows[name]
        print(f"{name:10s} wall {r['wall_s']['median'] * 1e3:6.1f} ms ({r['wall_s']['min'] * 1e3:.1f}-"
              f"{r['wall_s']['max'] * 1e3:.1f})  world {r['world_s']['median'] * 1e3:5.1f} ms  "
              f"({r['world_evaluations']} values, {r['talbot_calls']} Talbot calls)  {r['driver_reads']} driver reads")
    walls = [w["wall_s"] for rs in runs.values() for w in rs]
    medians = [r["wall_s"]["median"] for r in rows.values()]
    summary = {"median_wall_s": statistics.median(walls), "min_wall_s": min(walls), "max_wall_s": max(walls),
               "max_scene_median_wall_s": max(medians),
               "median_world_s": statistics.median([w["world_s"] for rs in runs.values() for w in rs])}
    print(f"one simulated 2-s touch: median {summary['median_wall_s'] * 1e3:.0f} ms "
          f"(min {summary['min_wall_s'] * 1e3:.0f}, max {summary['max_wall_s'] * 1e3:.0f} ms) wall over "
          f"{len(walls)} runs; world median {summary['median_world_s'] * 1e3:.1f} ms")
    path = write_json("sim_touch", {
        "what": "wall time of one simulated 2-s touch (scene load + drivers + 2 s heating, "
                "MCP9600 18-bit and ADS1115 860 SPS read every dt); per scene median and min-max over "
                "interleaved repeats",
        "command": "python bench/sim_touch_bench.py" + (f" --dt {args.dt}" if args.dt != 0.01 else "")
                   + (f" --repeat {args.repeat}" if args.repeat != 5 else ""),
        "dt_s": args.dt, "repeat": args.repeat, "scenes": rows, "summary": summary,
    })
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
