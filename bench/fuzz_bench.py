"""A time-bounded fuzz run of the device's request handling: every frame a reply or a clean refusal.

Random and mutated requests (seeded; JSON objects of the protocol's own keys with random values, random
bytes, every command byte and a few that are none) go straight into a simulated daemon's decoder and
handler, as ``tests/edge/service/test_daemon.py::test_fuzzed_requests_get_a_reply_or_a_clean_error``
does for 300 cases, but for ``--minutes`` of wall time. A case passes when it is refused as a
ProtocolError or a CommandError that is not INTERNAL, or answered with a reply that fits its schema and
size bound; the heater must be off after every case and never latched. Errors the daemon catches
inside a touch's estimate (the sensor chain's, logged and kept as the chain's ``error``) are counted by
exception type as ``caught_in_estimate``: the 10-minute run of 98d764d had two ZeroDivisionErrors there
(a chain fit window past a 0.7-s touch's end; now refused by name as a ValueError).

Run:  python bench/fuzz_bench.py [--minutes 10] [--seed 0]
Writes bench/results/fuzz.json.
"""

from __future__ import annotations

import argparse
import json
import random
import tempfile
import time
from pathlib import Path

from _common import write_json

KEYS = ["offset", "limit", "keys", "values", "measurement_id", "power_W", "voltage_V", "contact_time_s", "echo",
        "size", "sha256", "version", "downgrade", "which", "name", "text", "signature", "activate", "session",
        "until_decided", "arm_s", "settle_s", "sample_rate_Hz", "heater.power_W", "measurement.cooldown_s",
        "measurement.baseline_s", "measurement.sample_rate_Hz", "x"]


def _value(rng: random.Random, depth: int = 0):
    r = rng.random()
    if depth < 2 and r < 0.15:
        return [_value(rng, depth + 1) for _ in range(rng.randint(0, 4))]
    if depth < 2 and r < 0.25:
        return {rng.choice(KEYS): _value(rng, depth + 1) for _ in range(rng.randint(0, 4))}
    return rng.choice([None, True, False, rng.randint(-2**40, 2**40), rng.uniform(-1e6, 1e6), rng.random(),
                       rng.choice([0, 1, -1, 0.26, 0.001, 1e308]), "".join(rng.choice("ab\\\"\x1b=é\ud7ff0")
                                                                      for _ in range(rng.randint(0, 20)))])


def _payload(rng: random.Random) -> bytes:
    if rng.random() < 0.25:
        return bytes(rng.getrandbits(8) for _ in range(rng.randint(0, 64)))
    obj = {rng.choice(KEYS): _value(rng) for _ in range(rng.randint(0, 4))}
    return json.dumps(obj).encode()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    from edge.protocol.commands import Command
    from edge.protocol.errors import CommandError, ErrorCode, ProtocolError
    from edge.protocol.frame import Frame
    from edge.protocol.messages import decode_request, encode_reply
    from edge.service.daemon import Daemon
    from firmware_sim.rigs.daemon_rig import make_rig
    from tests.support.daemons import FakeEstimator, sim_config

    import logging  # noqa: PLC0415

    caught: dict[str, int] = {}

    class _Caught(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            msg = record.getMessage()
            if msg.startswith("sensor-chain estimate failed: "):
                kind = record.args[0].__class__.__name__ if record.args else "?"
                caught[kind] = caught.get(kind, 0) + 1
                if kind not in ("ValueError",):
                    examples.append(f"caught in the estimate: {kind}: {msg[:160]}")

    logging.getLogger("edge.estimation.seam").addHandler(_Caught(logging.WARNING))
    rng = random.Random(args.seed)
    types = [int(c) for c in Command] + [0x00, 0x7F, 0x85]
    counts = {"cases": 0, "refused_frame": 0, "refused_command": 0, "answered": 0, "internal": 0,
              "heater_left_on": 0, "unexpected": 0}
    examples: list[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        rig = make_rig()
        d = Daemon(sim_config(Path(tmp), measurement={"cooldown_s": 0.0, "baseline_s": 0.2}), rig.board,
                   estimator=FakeEstimator())
        t_end = time.monotonic() + 60.0 * args.minutes
        try:
            while time.monotonic() < t_end:
                counts["cases"] += 1
                mt, rid, payload = rng.choice(types), rng.getrandbits(32), _payload(rng)
                try:
                    req = decode_request(Frame(mt, rid, payload))
                except ProtocolError as e:
                    counts["refused_frame"] += 1
                    if e.code == ErrorCode.INTERNAL:
                        counts["internal"] += 1
                        examples.append(f"frame {mt:#x} {payload[:80]!r}: {e}")
                    continue
                try:
                    body = d.handle(req)
                    encode_reply(req.command, rid, body)
                    counts["answered"] += 1
                except CommandError as e:
                    counts["refused_command"] += 1
                    if e.code == ErrorCode.INTERNAL:
                        counts["internal"] += 1
                        examples.append(f"{req.command.name} {payload[:80]!r}: {e}")
                except Exception as e:  # noqa: BLE001 - what the run is for
                    counts["unexpected"] += 1
                    examples.append(f"{req.command.name} {payload[:80]!r}: {type(e).__name__}: {e}")
                if d.heater.is_on:
                    counts["heater_left_on"] += 1
        finally:
            latched = d.heater.disabled
            d.close()
    result = {"minutes": args.minutes, "seed": args.seed, **counts, "caught_in_estimate": caught,
              "heater_latched": latched,
              "examples": examples[:20],
              "clean": counts["internal"] == 0 and counts["unexpected"] == 0 and counts["heater_left_on"] == 0
              and latched is None and set(caught) <= {"ValueError"}}
    print(json.dumps({k: v for k, v in result.items() if k != "examples"}))
    for ex in examples[:20]:
        print("  ", ex)
    write_json("fuzz", result)


if __name__ == "__main__":
    main()
