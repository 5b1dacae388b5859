"""How long the serve loop is held by one request of each kind that does work (ISSUE #35 §7).

The tests (tests/edge/service/test_serve_work.py) bound the work between two watchdog beats in
work units -- rows parsed, records decoded -- because the simulator's clock does not see CPU time.
This bench puts seconds on those units on this machine: a simulated daemon's handler answers, in
process, an OBJECTS install of a 256-kB set (BEGIN, CHUNKs, COMMIT: the commit is the turn that
parses), a duplicate-name upload of the same size (refused), OBJECTS_LIST with MAX_SETS sets of
256 kB stored (after a restart: nothing cached in memory), and HISTORY pages of 100 records.
Each is compared with a quarter of ``WatchdogSec=10`` (the notifier's pet interval).

Run:  python bench/serve_work_bench.py [--repeats 3]
Writes bench/results/serve_work.json.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import logging
import tempfile
import time
from pathlib import Path

from _common import write_json

PET_INTERVAL_s = 10.0 / 4


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    logging.disable(logging.WARNING)

    from edge.protocol.commands import Command
    from edge.protocol.errors import CommandError
    from edge.protocol.frame import Frame
    from edge.protocol.messages import decode_request
    from edge.service.daemon import Daemon
    from edge.storage.history import History
    from edge.storage.objects_store import MAX_SET_BYTES, MAX_SETS
    from firmware_sim.rigs.daemon_rig import make_rig
    from tests.edge.service.test_serve_work import big_set
    from tests.support.daemons import FakeEstimator, sim_config

    def daemon(tmp: Path) -> Daemon:
        return Daemon(sim_config(tmp), make_rig().board, estimator=FakeEstimator())

    def call(d: Daemon, cmd: Command, body: dict) -> tuple[float, object]:
        req = decode_request(Frame(int(cmd), 1, json.dumps(body).encode()))
        t0 = time.perf_counter()
        try:
            out = d.handle(req)
        except CommandError as e:
            out = e
        return time.perf_counter() - t0, out

    def upload(d: Daemon, name: str, blob: bytes) -> float:
        begin = d.handle(decode_request(Frame(int(Command.OBJECTS_BEGIN), 1, json.dumps(
            {"name": name, "size": len(blob), "sha256": hashlib.sha256(blob).hexdigest()}).encode())))
        d.objects.chunk(0, blob, begin["session"])   # the bytes, as the CHUNKs leave them
        return call(d, Command.OBJECTS_COMMIT, {"session": begin["session"]})[0]

    times: dict[str, list[float]] = {"objects_install_256kB": [], "duplicate_check_256kB": [],
                                     f"objects_list_{MAX_SETS}_sets": [], "history_page_100": []}
    for rep in range(args.repeats):
        with tempfile.TemporaryDirectory() as tmp:
            d = daemon(Path(tmp))
            try:
                times["objects_install_256kB"].append(upload(d, "s0", big_set(f"r{rep}s0")))
                times["duplicate_check_256kB"].append(upload(d, "dup", big_set(f"r{rep}d", duplicate=True)))
                for i in range(1, MAX_SETS):
                    upload(d, f"s{i}", big_set(f"r{rep}s{i}"))
            finally:
                d.close()
            with History(Path(tmp) / "history.db") as h:
                for i in range(300):
                    h.add({"status": "ok", "flags": [], "result": {"effusivity_W_s05_m2K": 1000.0 + i,
                                                                 "object": f"o{i}", "flags": []}})
            d = daemon(Path(tmp))                    # restarted: nothing held in memory
            try:
                times[f"objects_list_{MAX_SETS}_sets"].append(call(d, Command.OBJECTS_LIST, {})[0])
                times["history_page_100"].append(call(d, Command.HISTORY, {"offset": 150, "limit": 100})[0])
            finally:
                d.close()
    result = {"pet_interval_s": PET_INTERVAL_s, "set_bytes": MAX_SET_BYTES, "repeats": args.repeats,
              "max_s": {k: max(v) for k, v in times.items()},
              "fraction_of_pet_interval": {k: max(v) / PET_INTERVAL_s for k, v in times.items()}}
    print(json.dumps(result, indent=1))
    write_json("serve_work", result)


if __name__ == "__main__":
    main()
