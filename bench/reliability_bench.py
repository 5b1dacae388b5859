"""Reliability figures: kill -9 at every step, signals mid-heating, stop latency, a host that stops reading.

Run::

    python bench/reliability_bench.py                  # writes bench/results/reliability.json
    python bench/reliability_bench.py --update-readme  # and the table in README.md "## Reliability"

What it measures (the same checks the tests make, counted instead of asserted):

* kill points (tests/support/killpoints.py, tests/edge/service/test_kill_points.py): for a
  MEASURE, a model flash through the upload path, six CONFIG_SETs, the daemon's start-up
  (first boot, and on what a killed daemon left), a signed CALIBRATION_SET and signed object-set
  uploads with activation (a new set, and over the active one), a forked daemon dies by
  SIGKILL before every step, and a restart checks that nothing was lost or half-written (for the
  installs also: ``signed_by`` names the signer of exactly the bytes in use, and the install is
  all or nothing); per operation: points found (by kind), survived, lost/half-written, median
  time per point, and full daemon restarts (no fault, heater off, measures again) at a few points;
* a frozen converter (tests/edge/hw/test_frozen_converter.py): each chip's conversions stop
  mid-heating (the simulator's ``converter_frozen``): how long until the heater is off, what the
  record says, whether the next touch measures;
* signals (tests/edge/service/test_process_safety.py): a real daemon process gets each catchable
  signal mid-heating, and SIGKILL; the enable line must be low afterwards and, for a catchable
  signal, the touch stored as aborted;
* stop latency (tests/edge/service/test_reliability.py): time for the daemon to stop when idle,
  measuring, uploading and with a writer blocked by a host that stopped reading;
* a host that stops reading: 3000 PINGs nobody reads, then a reconnect: replies dropped, time to
  the first answer, whether the daemon is still idle and answering.

"""

from __future__ import annotations

import argparse
import json
import logging
import signal
import statistics
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

from _common import ROOT, interleaved, write_block, write_json

STATES = ("idle", "measuring", "uploading", "blocked_writer")


def kill_points() -> dict:
    """Every kill point of every operation, and three full restarts per operation."""
    from tests.support import killpoints as K

    out = {}
    with K.work_root() as root:
        builds = (K.measure_operation, K.flash_operation, K.config_operation,
                  lambda r: K.startup_operation(r, after_crash=False),
                  lambda r: K.startup_operation(r, after_crash=True), K.calibration_operation,
                  K.objects_operation, lambda r: K.objects_operation(r, "kitchen"))
        for build in builds:
            op = build(root)
            t0 = time.perf_counter()
            trace, results = K.run_all(op, root)
            wall = time.perf_counter() - t0
            bad = [r for r in results if r.problems]
            restarts = []
            for n in sorted({1, len(trace) // 2, len(trace)}):
                res = K.kill_at(op, root, n, trace[n - 1], keep=True)
                rs = K.full_restart(root / f"{op.name}-k{n}" / "state")
                st = rs["status"]
                restarts.append(not res.problems and st["faults"] == [] and st["can_measure"]
                                and rs["heater_level"] == 0 and rs["pwm_duty"] == 0.0
                                and rs["measure"]["status"] == "ok" and rs["line_after_close"]["level"] == 0)
            out[op.name] = {
                "points": len(trace), "by_kind": dict(Counter(s.split("\t")[0] for s in trace)),
                "survived": len(results) - len(bad), "lost_or_half_written": len(bad),
                "problems": [f"#{r.n} {r.step}: {r.problems}" for r in bad][:20],
                "ms_per_point_median": statistics.median(r.seconds for r in results) * 1e3,
                "wall_s": wall, "full_restarts": len(restarts), "full_restarts_clean": sum(restarts)}
            print(f"{op.name}: {len(trace)} points {out[op.name]['by_kind']}, {len(bad)} broken, {wall:.2f} s",
                  flush=True)
    return out


#: (scene, chip frozen): the reference board's two converters and the precision board's one.
FROZEN_CASES = (("glass_15V", "mcp9600"), ("glass_15V", "ads1115"), ("alu_20V_ads122c04", "ads122c04"))


def frozen_converter(tmp: Path, into_heating_s: float = 1.0, frozen_s: float = 3.0) -> dict:
    """A converter frozen ``into_heating_s`` into the heating of a second touch, for ``frozen_s``: seconds from
    the freeze to the heater off (the board's virtual clock), the record, STATUS, and the next touch."""
    from edge.protocol.errors import CommandError
    from edge.service.daemon import Daemon
    from firmware_sim import load_scene
    from firmware_sim.run import config_for_scene
    from tests.support.daemons import FakeEstimator

    out = {}
    for scene, chip in FROZEN_CASES:
        sim = load_scene(scene)
        cfg = config_for_scene(sim.scene, tmp / f"{scene}-{chip}",
                               {"measurement": {"trigger_button": False, "cooldown_s": 2.0}})
        with Daemon(cfg, sim.board(), estimator=FakeEstimator()) as d:
            sim.advance_to(sim.scene.touch.start_s + 0.1)
            first = d.measure()["status"]
            t1 = sim.now()
            sim.add_touch(t1, 6.0, press_trigger=False)
            t_freeze = t1 + cfg.measurement.cooldown_s + cfg.measurement.baseline_s + into_heating_s
            sim.inject("converter_frozen", at_s=t_freeze, until_s=t_freeze + frozen_s, chip=chip)
            try:
                d.measure()
                error = None
            except CommandError as e:
                error = f"{e.code.name}: {e.message}"
            rec = d.history.get(d.history.count())
            on_a, on_b = sim.heater_intervals()[-1]
            st = d._cmd_status({})
            sim.advance_to(max(t_freeze + frozen_s, t1 + 6.0) + 0.01)  # thawed, the touch over
            sim.add_touch(sim.now(), 6.0, press_trigger=False)
            nxt = d.measure()["status"]
        out[f"{scene}:{chip}"] = {
            "first_touch": first, "heater_off_after_freeze_s": on_b - t_freeze if on_a < t_freeze else None,
            "sample_period_s": 1.0 / cfg.measurement.sample_rate_Hz, "record": [rec["status"], rec["reason"]],
            "error_names_chip": error is not None and chip in error, "can_measure": st["can_measure"],
            "faults": list(st["faults"]), "next_touch": nxt}
    return out


def _signal_names() -> list[str]:
    # The list the test parametrises over, so that bench and test cannot drift apart.
    from tests.edge.service import test_process_safety as T

    marks = T.test_every_catchable_signal_mid_heating_leaves_the_heater_off.pytestmark
    (sigs,) = [m.args[1] for m in marks if m.name == "parametrize"]
    return [signal.Signals(s).name for s in sigs]


def signals(tmp: Path) -> dict:
    """Each catchable signal, and SIGKILL, mid-heating of a real daemon process: is the heater off after?"""
    import serial
    from edge.protocol.commands import Command
    from edge.protocol.messages import encode_request
    from firmware_sim.gpiod.state import read_line

    script = ROOT / "tests" / "support" / "daemon_proc.py"
    out = {}
    for name in _signal_names() + ["SIGKILL"]:
        d = tmp / name
        d.mkdir()
        proc = subprocess.Popen([sys.executable, str(script), str(d)], stdout=subprocess.PIPE,
                                stderr=subprocess.DEVNULL, text=True)
        try:
            port = proc.stdout.readline().strip()
            with serial.Serial(port, timeout=0.05) as host:
                host.write(encode_request(Command.MEASURE, 1, {}))
                host.flush()
                heating = proc.stdout.readline().strip() == "HEATING"
                on_before = read_line(d / "gpio", "gpiochip0", 17)["level"]
                proc.send_signal(getattr(signal, name))
                stdout, _ = proc.communicate(timeout=30)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        line = read_line(d / "gpio", "gpiochip0", 17)
        rec = None
        if name != "SIGKILL":
            report = json.loads(stdout.strip().splitlines()[-1])
            rec = [[r["status"], r["reason"]] for r in report["records"]]  # lists: as in the JSON results
        ok = heating and on_before == 1 and line["level"] == 0 and (
            rec is None or rec == [["aborted", "stopped"]])
        out[name] = {"heater_off_after": line["level"] == 0, "was_heating": heating and on_before == 1,
                     "records": rec, "returncode": proc.returncode, "ok": ok}
    return out


def stop_latency(tmp: Path, repeats: int = 3) -> dict:
    """Seconds from stop to a joined daemon thread, in each state (as test_stop_is_prompt_in_every_state).

    The states take turns (:func:`_common.interleaved`), so a busy spell of the machine does not
    land on one state only; only the stop itself is timed, not the set-up of the state.
    """
    from edge.service.config import Config
    from tests.edge.service.test_reliability import daemon_in_state
    from tests.support.daemons import assert_heater_safe

    lat: dict[str, list[float]] = {state: [] for state in STATES}

    def trial(state: str) -> None:
        d_tmp = tmp / f"stop-{state}-{len(lat[state])}"
        d_tmp.mkdir()
        with daemon_in_state(d_tmp, state, wait_s=20) as (dt, rig):
            t0 = time.monotonic()
            dt.stop(20)
            lat[state].append(time.monotonic() - t0)
        assert_heater_safe(rig.parts, Config().heater.max_on_time_s)

    interleaved({state: (lambda s=state: trial(s)) for state in STATES}, repeats, warmup=False)
    return {state: {"median_s": statistics.median(v), "max_s": max(v), "n": len(v)} for state, v in lat.items()}


def host_stops_reading(tmp: Path, silent_s: float = 60.0) -> dict:
    """3000 PINGs nobody reads for ``silent_s``, then a reconnect (as
    test_host_that_stops_reading_does_not_wedge_the_daemon, which is silent for 1 s)."""
    import serial
    from firmware_sim.daemon_thread import DaemonThread
    from firmware_sim.ptylink import NullModem
    from firmware_sim.rigs.daemon_rig import make_rig
    from host.client import DeviceClient
    from tests.edge.service.test_reliability import _flood
    from tests.support.daemons import FakeEstimator, sim_config

    rig = make_rig()
    with NullModem() as nm, serial.Serial(nm.device_port, timeout=0.05) as port:
        dt = DaemonThread(sim_config(tmp), rig.board, port, estimator=FakeEstimator())
        dt.start()
        try:
            _flood(nm.host_port, 3000, 100_000, silent_s=silent_s)
            t0 = time.monotonic()
            with DeviceClient(nm.host_port, timeout_s=5.0) as c:
                pong = c.ping("back")
                back_s = time.monotonic() - t0
                st = c.status()
        finally:
            dt.stop(20)
    return {"pings_sent": 3000, "silent_s": silent_s, "replies_dropped": st["replies_dropped"], "answer_after_reconnect_s": back_s,
            "state_after": st["state"], "wedged": not (pong == {"echo": "back"} and st["state"] == "idle")}


def table(res: dict) -> str:
    """The docs/results.md block."""
    kp = res["kill_points"]
    lines = ["| operation | kill points (by kind) | survived | lost / half-written | full restarts clean "
             "| ms per point |", "|---|---|---|---|---|---|"]
    for name, r in kp.items():
        kinds = ", ".join(f"{k} {v}" for k, v in r["by_kind"].items())
        lines.append(f"| {name} | {r['points']} ({kinds}) | {r['survived']} | {r['lost_or_half_written']} | "
                     f"{r['full_restarts_clean']} of {r['full_restarts']} | {r['ms_per_point_median']:.0f} |")
    total = sum(r["points"] for r in kp.values())
    survived = sum(r["survived"] for r in kp.values())
    core = sum(kp[k]["points"] for k in ("measure", "flash", "config"))
    sig = res["signals"]
    stop = res["stop_latency"]
    h = res["host_stops_reading"]
    installs = [k for k in kp if k == "calibration" or k.startswith("objects")]
    fz = res["frozen_converter"]
    lines += ["", f"{survived} of {total} kill points survive ({core} of them in measure, flash and config; "
              f"{sum(kp[k]['points'] for k in installs)} in the signed installs, where the data in use, its "
              "`signed_by` and the install's all-or-nothing are checked after each restart).", "",
              "A converter frozen 1 s into the heating (`converter_frozen`): "
              + "; ".join(f"{k} -> heater off {v['heater_off_after_freeze_s']:.2f} s later "
                          f"({v['heater_off_after_freeze_s'] / v['sample_period_s']:.1f} sample periods), record "
                          f"{'/'.join(v['record'])}, can_measure {str(v['can_measure']).lower()}, "
                          f"next touch {v['next_touch']}" for k, v in fz.items()) + ".", "",
              f"Signals mid-heating with the heater off afterwards: {sum(v['ok'] for v in sig.values())} of "
              f"{len(sig)} ({', '.join(sig)}); the touch stored as aborted (`stopped`) after "
              f"{sum(v['records'] == [['aborted', 'stopped']] for v in sig.values())} "
              f"of the {sum(v['records'] is not None for v in sig.values())} catchable ones.", "",
              "Stop latency, median [max] of " + str(next(iter(stop.values()))["n"]) + ": "
              + ", ".join(f"{k} {v['median_s'] * 1e3:.0f} [{v['max_s'] * 1e3:.0f}] ms" for k, v in stop.items())
              + ".", "",
              f"A host that stops reading for {h['silent_s']:g} s ({h['pings_sent']} PINGs unread): {h['replies_dropped']} replies dropped, "
              f"answered {h['answer_after_reconnect_s'] * 1e3:.0f} ms after the reconnect, state "
              f"`{h['state_after']}`, {'wedged' if h['wedged'] else 'not wedged'}."]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--update-readme", action="store_true", help="write the table into docs/results.md")
    ap.add_argument("--silent-s", type=float, default=60.0, help="how long the host stops reading (default 60 s)")
    args = ap.parse_args(argv)
    logging.disable(logging.WARNING)  # the daemons' own warnings (stray temporaries removed...) are expected
    import tempfile

    with tempfile.TemporaryDirectory(prefix="thermotouch-reliability-") as t:
        tmp = Path(t)
        (tmp / "signals").mkdir()
        (tmp / "stop").mkdir()
        (tmp / "flood").mkdir()
        (tmp / "frozen").mkdir()
        res = {"kill_points": kill_points(), "frozen_converter": frozen_converter(tmp / "frozen"),
               "signals": signals(tmp / "signals"),
               "stop_latency": stop_latency(tmp / "stop"), "host_stops_reading": host_stops_reading(tmp / "flood", args.silent_s)}
    path = write_json("reliability", res)
    text = table(res)
    print(text)
    print(f"wrote {path.relative_to(ROOT)}")
    if args.update_readme:
        write_block("reliability-bench", text)
        print("docs/results.md updated")
    broken = sum(r["lost_or_half_written"] for r in res["kill_points"].values())
    frozen_ok = all(v["record"] == ["failed", "sensor_fault"] and v["can_measure"] and v["next_touch"] == "ok"
                    for v in res["frozen_converter"].values())
    return 1 if broken or not frozen_ok or not all(v["ok"] for v in res["signals"].values()) else 0


if __name__ == "__main__":
    sys.exit(main())
