"""Daemon benchmark: resident memory, compute time after the last sample, and a soak.

The daemon runs in a child process on the simulator (firmware_sim.rigs.daemon_rig:
sim board, MCP9600 + ADS1115 models, an analytic glass-like sample) with its
real estimator and the shipped model bundle (a stand-in estimator if none is
installed), behind a virtual null-modem cable. This process is the host: it
sends N MEASURE requests over the serial link with host.client.DeviceClient
and samples the child's resident memory (VmRSS) and open file descriptors.

Reported (bench/results/daemon.json):

* ``rss_MB``: the daemon process's VmRSS after warm-up and at the end
  (includes the simulator living in the same process); ``rss_edge_only_MB``:
  a process that imports the daemon's modules and loads the estimator on
  the shipped bundle (what a Pi runs, minus the simulator);
* ``compute_ms``: wall time from the last sample (heater already off) to the
  result -- quality flags, resampling and estimation, and the sensor chain's
  estimate from contact (``chain_ms`` alone) -- median / p95 / max;
  ``compute_and_commit_ms`` adds the durable SQLite commit;
* soak: RSS growth and fd count change from measurement 10 to N, live
  objects gained per package (edge vs the simulator's own history), the heater
  invariant read from the simulated GPIO/PWM history (longest on-interval,
  off at the end), and how many measurements came back ``ok``.

Usage::

    python bench/daemon_bench.py            # N = 1000
    python bench/daemon_bench.py --n 200
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))


def _rss_MB(pid: int | str = "self") -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    raise RuntimeError("no VmRSS")


def _n_fds(pid: int) -> int:
    return len(os.listdir(f"/proc/{pid}/fd"))


# --------------------------------------------------------------------------- child


def child(workdir: str) -> int:
    import serial

    from edge.service.config import Config
    from firmware_sim.daemon_thread import DaemonThread
    from firmware_sim.rigs.daemon_rig import heater_invariant, make_rig
    from firmware_sim.ptylink import NullModem

    w = Path(workdir)
    cfg = Config({
        "board": {"kind": "sim"},
        "heater": {"supply_voltage_V": 15.0, "resistance_ohm": 44.0, "power_W": 5.0},
        "measurement": {"cooldown_s": 5.0, "trigger_button": False},
        "paths": {"model_store": str(w / "models"), "history_db": str(w / "history.sqlite3"),
                  "runtime_overrides": str(w / "runtime.json")},
        "logging": {"level": "WARNING"},
    }, source="bench")
    rig = make_rig(effusivity=1474.0, T_noise_V=1e-6, flux_noise_V=2e-6, seed=1)
    estimator = None
    try:
        from edge.estimation.estimate import pipeline_golden_check
        from edge.model.store import ModelStore
        from thermotouch_models import DEFAULT_BUNDLE

        ModelStore(w / "probe-store", DEFAULT_BUNDLE, golden_check=pipeline_golden_check).current()
        estimator_kind = "edge.estimation.estimate on the shipped bundle"
    except Exception as e:  # no shipped bundle yet: a physics stand-in keeps the soak meaningful
        import math

        import numpy as np

        def estimator(t, dT, q, power_W, method):
            e = 2.0 * float(np.mean(q)) * math.sqrt(t[-1] / math.pi) / max(float(dT[-1]), 1e-9)
            return {"effusivity_W_s05_m2K": e, "effusivity_W_s05_m2K_u": 0.05 * e, "flags": []}

        estimator_kind = f"stand-in ({type(e).__name__}: {e})"
    timings: list[dict] = []
    nm = NullModem()
    port = serial.Serial(nm.device_port, timeout=0.05)
    dt = DaemonThread(cfg, rig.board, port, estimator=estimator)
    d = dt.start()
    measure = d.measure

    census: dict[str, object] = {}

    def object_census() -> dict[str, int]:
        """Live gc-tracked objects per defining package: which side of the simulation grows."""
        import collections
        import gc

        gc.collect()
        c: collections.Counter = collections.Counter()
        for o in gc.get_objects():
            mod = getattr(type(o), "__module__", "")
            top = mod.split(".")[0] if isinstance(mod, str) else ""
            c[top if top in ("edge", "firmware_sim") else f"other:{type(o).__name__}"] += 1
        return dict(c)

    def timed_measure(**kw):
        try:
            return measure(**kw)
        finally:
            timings.append(dict(d.last_timing))
            if len(timings) == 10:
                census["after_10"] = object_census()
                census["blocks_after_10"] = sys.getallocatedblocks()

    d.measure = timed_measure
    print(nm.host_port, flush=True)
    sys.stdin.readline()  # the parent says when to stop
    dt.stop()
    port.close()
    nm.close()
    end = object_census()
    start = census.get("after_10", {})
    growth = {k: end.get(k, 0) - start.get(k, 0) for k in set(end) | set(start)}
    growth = dict(sorted(((k, v) for k, v in growth.items() if v), key=lambda kv: -abs(kv[1]))[:8])
    blocks = sys.getallocatedblocks() - int(census.get("blocks_after_10", 0))
    inv = heater_invariant(rig.parts, cfg.heater.max_on_time_s)
    print(json.dumps({"timings": timings, "invariant": inv, "estimator": estimator_kind,
                      "object_growth_10_to_end": growth, "python_blocks_growth_10_to_end": blocks,
                      "max_on_time_s": cfg.heater.max_on_time_s, "daemon_error": repr(dt.error)}), flush=True)
    return 0


def edge_only_rss() -> float:
    code = (
        "import sys; sys.path.insert(0, %r)\n"
        "import edge.service.daemon, edge.estimation.estimate, serial, sqlite3\n"
        "from thermotouch_models import DEFAULT_BUNDLE\n"
        "from edge.model.bundle import load_bundle\n"
        "b = load_bundle(DEFAULT_BUNDLE, golden_check=edge.estimation.estimate.pipeline_golden_check)\n"
        "edge.estimation.estimate.Estimator.from_bundle(b)\n"
        "for l in open('/proc/self/status'):\n"
        "    if l.startswith('VmRSS:'): print(int(l.split()[1]) / 1024.0)\n"
    ) % str(ROOT)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    if out.returncode != 0:   # say why, never a silent NaN in the results
        raise SystemExit(f"edge-only RSS probe failed:\n{out.stderr.strip()}")
    return float(out.stdout.strip().splitlines()[-1])


# --------------------------------------------------------------------------- parent


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1000, help="measurements in the soak (default 1000)")
    ap.add_argument("--child", metavar="WORKDIR", help=argparse.SUPPRESS)
    ap.add_argument("--update-readme", action="store_true", help="rewrite the daemon-bench block in docs/results.md")
    a = ap.parse_args(argv)
    if a.child:
        return child(a.child)
    if a.n < 20:
        ap.error("--n must be >= 20")

    from _common import write_block, write_json
    from host.client import DeviceClient

    with tempfile.TemporaryDirectory(prefix="daemon-bench-") as workdir:
        proc = subprocess.Popen([sys.executable, __file__, "--child", workdir], stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        stderr_lines: list[str] = []
        threading.Thread(target=lambda: stderr_lines.extend(proc.stderr), daemon=True).start()
        try:
            port = proc.stdout.readline().strip()
            if not port.startswith("/dev/"):
                raise SystemExit(f"child failed: {''.join(stderr_lines)}")
            samples = []
            statuses: dict[str, int] = {}
            t0 = time.perf_counter()
            with DeviceClient(port, timeout_s=10.0) as c:
                info = c.info()
                for i in range(a.n):
                    try:
                        rec = c.measure()
                        statuses[rec["status"]] = statuses.get(rec["status"], 0) + 1
                    except Exception as e:  # counted, the soak goes on
                        key = type(e).__name__
                        statuses[key] = statuses.get(key, 0) + 1
                    if i == 9 or (i + 1) % 50 == 0 or i == a.n - 1:
                        samples.append({"i": i + 1, "rss_MB": round(_rss_MB(proc.pid), 2),
                                        "fds": _n_fds(proc.pid)})
                        print(f"{i + 1:5d}  rss {samples[-1]['rss_MB']:.1f} MB  fds {samples[-1]['fds']}",
                              file=sys.stderr, flush=True)
                total = c.history(0, 1)["total"]
            wall = time.perf_counter() - t0
            proc.stdin.write("stop\n")
            proc.stdin.flush()
            out, _ = proc.communicate(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    if not out.strip():
        raise SystemExit(f"daemon child failed (exit {proc.returncode}):\n{''.join(stderr_lines)}")
    report = json.loads(out.strip().splitlines()[-1])
    comp = [t["compute_s"] * 1e3 for t in report["timings"] if t.get("compute_s") is not None]
    comm = [t["compute_and_commit_s"] * 1e3 for t in report["timings"] if t.get("compute_and_commit_s") is not None]

    def stats(xs):
        xs = sorted(xs)
        return {"median": round(statistics.median(xs), 3), "p95": round(xs[int(0.95 * (len(xs) - 1))], 3),
                "max": round(xs[-1], 3), "n": len(xs)} if xs else None

    first = samples[0]
    last = samples[-1]
    inv = report["invariant"]
    result = {
        "command": f"python bench/daemon_bench.py --n {a.n}",
        "n_measurements": a.n,
        "estimator": report["estimator"],
        "model_sha256": info.get("model_sha256"),
        "statuses": statuses,
        "history_total": total,
        "wall_s": round(wall, 2),
        "wall_per_measurement_ms": round(wall / a.n * 1e3, 2),
        "rss_MB": {"after_10": first["rss_MB"], "end": last["rss_MB"], "max": max(s["rss_MB"] for s in samples)},
        "rss_growth_MB_10_to_end": round(last["rss_MB"] - first["rss_MB"], 2),
        "rss_edge_only_MB": round(edge_only_rss(), 2),
        "fds": {"after_10": first["fds"], "end": last["fds"]},
        "object_growth_10_to_end": report["object_growth_10_to_end"],
        "python_blocks_growth_10_to_end": report["python_blocks_growth_10_to_end"],
        "compute_ms": stats(comp),
        "chain_ms": stats([t["chain_s"] * 1e3 for t in report["timings"] if t.get("chain_s") is not None]),
        "compute_and_commit_ms": stats(comm),
        "heater_invariant": inv,
        "heater_invariant_ok": bool(inv["ok"]) and inv["n_intervals"] == a.n,
        "max_on_time_s": report["max_on_time_s"],
        "targets": {"rss_MB": 80, "compute_median_ms": 20},
        "rss_samples": samples,
    }
    path = write_json("daemon", result)
    show = {k: v for k, v in result.items() if k != "rss_samples"}
    print(json.dumps(show, indent=1))
    print(f"wrote {path}", file=sys.stderr)
    if a.update_readme:
        write_block("daemon-bench", readme_text(result))
    return 0


def readme_text(r: dict) -> str:
    """The daemon figures of docs/results.md, from one run's results."""
    growth = r["object_growth_10_to_end"]
    edge_grew = {k: v for k, v in growth.items() if k.startswith("edge") and v > 0}
    c, ch, cc, inv = r["compute_ms"], r["chain_ms"], r["compute_and_commit_ms"], r["heater_invariant"]
    return (f"Daemon figures (`{r['command']} --update-readme`, `bench/results/daemon.json`;\n"
            "the daemon runs in a child process with the simulated board in the same process, the bench is\n"
            f"the host over the virtual serial link): resident memory {r['rss_MB']['after_10']:.1f} MB after 10\n"
            f"measurements and {r['rss_MB']['end']:.1f} MB after {r['n_measurements']} ({r['rss_edge_only_MB']:.1f} MB "
            "for the daemon's modules and the estimator alone;\n"
            f"target {r['targets']['rss_MB']} MB) -- the {r['rss_growth_MB_10_to_end']:.1f} MB of growth is the "
            "simulated world's history,\n"
            f"while the daemon's own object count {'grew: ' + str(edge_grew) if edge_grew else 'did not grow'}; "
            f"compute from the last sample to the result,\nthe sensor chain's estimate from contact included, "
            f"median {c['median']:.1f} ms (p95 {c['p95']:.1f} ms; target {r['targets']['compute_median_ms']} ms), "
            + (f"of which the chain {ch['median']:.1f} ms;\n" if ch else "(the chain's share is no longer timed apart: "
               "it is one step of the one estimate path);\n")
            + f"{cc['median']:.1f} ms with the durable database commit; "
            f"{r['n_measurements']} measurements in a row, {r['statuses'].get('ok', 0)} ok and "
            f"{r['history_total']} stored,\nfile descriptors {r['fds']['after_10']} → {r['fds']['end']}, heater on "
            f"at most {inv['longest_on_s']:.3f} s per touch against a {r['max_on_time_s']:g} s\nlimit, "
            f"{'off' if inv['off_now'] else 'ON'} at the end.")


if __name__ == "__main__":
    sys.exit(main())
