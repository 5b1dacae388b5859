"""Kill -9 at every step of a device operation, restart, and check that nothing was lost or half-written.

An *operation* (a MEASURE, a model flash, a run of CONFIG_SETs, the daemon's start-up, a signed
CALIBRATION_SET, a signed object-set upload with activation) is a list of protocol requests
that a daemon built on the simulated rig answers. A *step* is anything the operation does that
outlives the process:

* ``file``: every ``os.open(O_CREAT)``, ``os.write``, ``os.fsync``, ``os.replace``,
  ``os.rename``, ``os.mkdir``, ``os.unlink`` and ``os.rmdir`` made from
  :mod:`edge.storage.durable`, :mod:`edge.model.store`, the bundle modules of :mod:`edge.model`,
  :mod:`edge.service.config` or the calibration and object-set stores (found by the caller's
  stack, so ``shutil.rmtree`` and ``Path.unlink`` inside ``durable.remove_tree`` count, step by step);
* ``sqlite``: every writing statement the history issues (``BEGIN``, ``INSERT``, ``COMMIT``; at
  start-up ``PRAGMA journal_mode``, ``CREATE TABLE``, ``PRAGMA user_version``); SQLite's own page
  writes (and its WAL recovery) happen inside one C call and cannot be split from Python;
* ``heater``: every write to the simulated hardware that drives the heater (PWM sysfs files,
  the enable line);
* ``sample``: every sensor read of the touch (the heater is on during most of them; a kill there
  is the case the enable line's pull-down exists for);
* ``host``: the reply going to the host (killed before it, the host was never told);
* ``end``: after the last reply (everything confirmed).

:func:`dry_run` runs the operation once in a forked child and lists its steps. :func:`kill_at`
forks again, and the child kills itself with ``SIGKILL`` right before step N (``end``: right
after the last reply), so no ``finally``, ``atexit`` or signal handler runs -- exactly what
``kill -9`` or the OOM killer does. Right after step N is right before step N+1 as far as
anything outside the process can tell, so "before every step, and after the last" covers both.
The parent then *restarts*: it opens the history, the model store and the runtime overrides
fresh, as the daemon does at start-up, and checks the operation's invariants
(:class:`Operation.check`). Instrumentation is monkeypatched into the
child only; production code has no hooks.

Forking from the test process keeps a point at a few tens of ms (everything is imported, the
work directory is on tmpfs when there is one); a fresh interpreter per point would cost ~0.4 s.
Given a :class:`tests.support.daemon_proc.ForkServer`, the children are forked from that small
interpreter instead: the operation is rebuilt there from its description (:meth:`Operation.spec`),
warmed up once, and each child is its fork. A fork copies the forking process's page tables and
its children fault in copies of what they touch, so forking from a test worker that has grown to
hundreds of megabytes costs ~25 ms more a point than forking from the server. Children of the test
process itself (no server) inherit whatever the test monkeypatched; on a server, the harness's own
"is it vacuous" tests name their fault instead (:attr:`Operation.faults`,
:mod:`tests.support.killpoint_faults`), which each child puts in before it starts.
:func:`run_all` runs two children at a time (:data:`tests.support.killpoint_runner.KILL_JOBS`) and
checks a dead child's state while the next runs: a point is CPU work (the child's daemon start and
the operation up to the point, the test process's check), not waiting, so two keep both cores busy.
SIGKILL does not drop the page cache, so tmpfs and a disk behave the same for these kills
(power cuts are :mod:`tests.edge.model.test_store`'s business).

Modules: :mod:`tests.support.killpoint_steps` (steps and the child's instrumentation),
:mod:`tests.support.killpoint_runner` (operations, children, restarts),
:mod:`tests.support.killpoint_installs` (the signed installs: CALIBRATION_SET, and an object-set
upload with activation, each checked for its signature and all-or-nothing); this module holds the
four operations (MEASURE, a model flash, CONFIG_SETs, start-up) and re-exports the rest.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import tempfile
from pathlib import Path
from typing import Any, Callable

from edge.protocol.commands import Command
from tests.support.killpoint_runner import (EXIT_CRASHED, Operation, PointResult, child_daemon, dry_run, full_restart,
                                            heater_line, kill_at, open_model_store, run_all, warm_up, work_root)
from tests.support.killpoint_installs import calibration_operation, objects_operation
from tests.support.killpoint_steps import WATCHED_MODULES, Steps

__all__ = ["Steps", "Operation", "PointResult", "warm_up", "dry_run", "kill_at", "run_all", "work_root",
           "child_daemon", "full_restart", "measure_operation", "flash_operation", "config_operation",
           "startup_operation", "calibration_operation", "objects_operation", "CONFIG_KEYS", "CONFIG_VALUES",
           "WATCHED_MODULES"]

# ---------------------------------------------------------------------------------------------- the three operations

_SERIES = ("raw_t_s", "raw_T_C", "raw_q_W_m2")


def _history_rows(db: Path) -> tuple[list[str], dict[int, tuple]]:
    """Open the history as the daemon does, then (problems, {id: full row}) read with plain SQL."""
    from edge.storage.history import History, HistoryError

    problems: list[str] = []
    try:
        h = History(db)  # WAL recovery happens here, as at the daemon's start
    except HistoryError as e:
        return [f"history does not open after the kill: {e}"], {}
    try:
        check = h._db.execute("PRAGMA integrity_check").fetchall()
        if check != [("ok",)]:
            problems.append(f"integrity_check: {check[:3]}")
        cur = h._db.execute("SELECT * FROM measurements ORDER BY id")
        cols = [c[0] for c in cur.description]
        rows = {int(r[0]): dict(zip(cols, r)) for r in cur.fetchall()}
    finally:
        h.close()
    for mid, r in rows.items():
        n = r["n_samples"]
        for name in _SERIES:
            if r[name] is None or len(r[name]) != 8 * n:
                problems.append(f"measurement {mid}: {name} holds {None if r[name] is None else len(r[name]) // 8} "
                                f"values, n_samples says {n} (half-written)")
        try:
            json.loads(r["config"]), json.loads(r["flags"])
            if r["result"] is not None:
                json.loads(r["result"])
        except (TypeError, ValueError) as e:
            problems.append(f"measurement {mid}: a JSON column does not parse ({e})")
    return problems, rows


def _row_digest(row: dict) -> str:
    return hashlib.sha256(repr(sorted(row.items())).encode()).hexdigest()


def _heater_problems(point: Path) -> list[str]:
    line = heater_line(point)
    if line is None:
        return ["the enable line was never mirrored"]
    return [] if line["level"] == 0 else [f"heater enable line high after the kill: {line}"]


def measure_operation(root: Path, n_prior: int = 2) -> Operation:
    """One MEASURE with the configured touch, on a history that already holds ``n_prior`` records."""
    from firmware_sim.rigs.daemon_rig import make_rig
    from edge.service.daemon import Daemon
    from tests.support.daemons import FakeEstimator, sim_config

    template = Path(tempfile.mkdtemp(prefix="measure-template-", dir=root))
    scratch = Path(tempfile.mkdtemp(prefix="measure-template-hw-", dir=root))
    rig = make_rig(gpio_state_dir=scratch / "gpio", pwm_root=scratch / "pwm")
    with Daemon(sim_config(template), rig.board, estimator=FakeEstimator()) as d:
        for _ in range(n_prior):
            d.measure(contact_time_s=0.5)
    shutil.rmtree(scratch)
    problems, prior = _history_rows(template / "history.db")
    assert not problems and len(prior) == n_prior, problems
    prior_digest = {mid: _row_digest(r) for mid, r in prior.items()}

    def check(point: Path, replies: list[dict]) -> list[str]:
        problems, rows = _history_rows(point / "history.db")
        for mid, digest in prior_digest.items():
            if mid not in rows:
                problems.append(f"measurement {mid}, stored before the operation, is gone")
            elif _row_digest(rows[mid]) != digest:
                problems.append(f"measurement {mid}, stored before the operation, changed")
        new = sorted(set(rows) - set(prior_digest))
        if len(new) > 1:
            problems.append(f"one MEASURE left {len(new)} new records: {new}")
        for rep in replies:
            body = rep["body"]
            if rep["command"] != "MEASURE" or "measurement_id" not in body:
                problems.append(f"unexpected reply {rep}")
                continue
            row = rows.get(body["measurement_id"])
            if row is None:
                problems.append(f"measurement {body['measurement_id']} was confirmed to the host and is lost")
            elif (row["status"], row["n_samples"]) != (body["status"], body["n_samples"]):
                problems.append(f"measurement {body['measurement_id']} differs from what the host was told")
        return problems + _heater_problems(point)

    return Operation("measure", template, [(Command.MEASURE, {})], check, root, ("sqlite", "heater"))


def _variant_blobs(tags: tuple[str, ...]) -> dict[str, bytes]:
    """Transport blobs of the shipped bundle under new identities (its manifest's description differs)."""
    from edge.model.bundle import BUNDLE_FILES, MANIFEST_FILE, pack_entries
    from thermotouch_models import DEFAULT_BUNDLE

    out = {}
    for tag in tags:
        files = {name: (DEFAULT_BUNDLE / name).read_bytes() for name in BUNDLE_FILES}
        manifest = json.loads(files[MANIFEST_FILE])
        manifest["description"] = f"kill-point test model {tag}"
        manifest["model_version"] = f"killpts-{tag}"
        files[MANIFEST_FILE] = (json.dumps(manifest, indent=2, sort_keys=True) + "\n").encode()
        out[tag] = pack_entries([(name.encode(), files[name]) for name in BUNDLE_FILES])
    return out




def flash_operation(root: Path, chunk_bytes: int = 48 * 1024) -> Operation:
    """A model flash through the daemon's upload path (MODEL_BEGIN, MODEL_CHUNKs, MODEL_COMMIT).

    The store already holds two installs (``current`` = B, ``previous`` = A), so the flash of C
    rewrites both pointers and collects A.
    """
    from edge.storage.history import History

    template = Path(tempfile.mkdtemp(prefix="flash-template-", dir=root))
    History(template / "history.db").close()
    blobs = _variant_blobs(("A", "B", "C"))
    store = open_model_store(template)
    sha = {tag: store.install(blobs[tag], hashlib.sha256(blobs[tag]).hexdigest(), len(blobs[tag])).sha256
           for tag in ("A", "B")}
    blob = blobs["C"]
    blob_sha = hashlib.sha256(blob).hexdigest()
    requests: list[tuple[Command, dict]] = [(Command.MODEL_BEGIN, {"size": len(blob), "sha256": blob_sha,
                                                                    "version": "killpts-C"})]
    for off in range(0, len(blob), chunk_bytes):
        requests.append((Command.MODEL_CHUNK, {"offset": off, "data": blob[off:off + chunk_bytes]}))
    requests.append((Command.MODEL_COMMIT, {}))
    states = None  # (current, previous) pairs a restart may find; C's identity is known after the dry run

    def check(point: Path, replies: list[dict]) -> list[str]:
        nonlocal states
        problems: list[str] = []
        committed = [r["body"] for r in replies if r["command"] == "MODEL_COMMIT"]
        if committed and "bundle_sha256" not in committed[0]:
            return [f"MODEL_COMMIT refused: {committed[0]}"]
        if committed and states is None:
            c = committed[0]["bundle_sha256"]
            states = {(sha["B"], sha["A"]): "old", (sha["B"], sha["B"]): "old", (c, sha["B"]): "new"}
        st = open_model_store(point)  # start-up cleaning happens here, as in the daemon
        try:
            active = st.current()
        except Exception as e:  # noqa: BLE001 - any failure to serve a model is what we look for
            return [f"no model after the kill: {e}"] + _heater_problems(point)
        pointers = (st._read_pointer(st.CURRENT), st._read_pointer(st.PREVIOUS))
        if st.source != "current" or active.sha256 != pointers[0]:
            problems.append(f"served {st.source} ({active.sha256[:12]}), boot errors {st.boot_errors}")
        if states is not None and pointers not in states:
            problems.append(f"pointers {[p[:12] if p else p for p in pointers]} are neither the old nor the new state")
        if committed and states is not None and states.get(pointers) != "new":
            problems.append("the flash was confirmed to the host but the old model is active")
        if pointers[1] != pointers[0]:  # current() has just verified the bundle ``current`` names
            try:
                st._load_verified(st._bundle_path(pointers[1]), pointers[1])  # hashes, schema, golden vectors
            except Exception as e:  # noqa: BLE001
                problems.append(f"previous names a bundle that does not verify (no rollback): {e}")
        leftovers = sorted(os.listdir(st.tmp_dir)) + [e for e in os.listdir(st.root) if e.startswith(".")]
        unreferenced = sorted(set(os.listdir(st.bundles_dir)) - set(pointers))
        if leftovers:
            problems.append(f"stray temporaries survive start-up: {leftovers}")
        if unreferenced:
            problems.append(f"unreferenced bundles survive start-up: {[u[:12] for u in unreferenced]}")
        return problems + _heater_problems(point)

    return Operation("flash", template, requests, check)


#: A new value for every runtime key (each valid on the sim board, each unlike the default).
CONFIG_VALUES: dict[str, Any] = {
    "heater.power_W": 3.0, "measurement.baseline_s": 0.8, "measurement.contact_time_s": 1.5,
    "measurement.sample_rate_Hz": 5.0, "measurement.cooldown_s": 2.0,
    "measurement.no_contact_e_W_s05_m2K": 20.0, "measurement.decide_posterior": 0.9,
    "measurement.decide_min_s": 0.5, "measurement.noise_T_K": 0.2, "measurement.noise_q_W_m2": 60.0,
    "measurement.unstable_baseline_K": 0.3, "estimation.method": "paper", "logging.level": "WARNING",
}


#: The CONFIG_SETs of the operation: both string keys and four float keys of three sections (every key
#: takes the same path through the daemon; all 13 would only repeat it, at 7 points each).
CONFIG_KEYS = ("heater.power_W", "measurement.contact_time_s", "measurement.sample_rate_Hz",
               "measurement.decide_posterior", "estimation.method", "logging.level")


def config_operation(root: Path, keys: tuple[str, ...] | None = None) -> Operation:
    """One CONFIG_SET per runtime key, in order; the overrides file already holds one value."""
    from edge.service.config import RuntimeOverrides
    from edge.storage.history import History
    from tests.support.daemons import sim_config

    keys = CONFIG_KEYS if keys is None else keys
    template = Path(tempfile.mkdtemp(prefix="config-template-", dir=root))
    History(template / "history.db").close()
    (template / "runtime.json").write_text(json.dumps({"heater.power_W": 2.0}))
    base = sim_config(template)
    old = RuntimeOverrides(template / "runtime.json").load(base)
    requests = [(Command.CONFIG_SET, {"values": {k: CONFIG_VALUES[k]}}) for k in keys]

    def check(point: Path, replies: list[dict]) -> list[str]:
        problems: list[str] = []
        path = point / "runtime.json"
        ro = RuntimeOverrides(path)
        ro.clean_temporaries()  # what the daemon does first at start-up
        stray = [p for p in os.listdir(point) if p.startswith(".runtime.json")]
        if stray:
            problems.append(f"stray temporaries survive start-up: {stray}")
        try:
            data = json.loads(path.read_text("utf-8"))
            assert isinstance(data, dict)
        except (OSError, ValueError, AssertionError) as e:
            return problems + [f"runtime overrides unreadable after the kill: {e}"]
        cfg = ro.load(sim_config(point))
        if ro.errors:
            problems.append(f"overrides refused at start-up: {ro.errors}")
        state = ["new" if cfg.get(k) == CONFIG_VALUES[k] else "old" if cfg.get(k) == old.get(k) else "other"
                 for k in keys]
        if "other" in state:
            problems.append(f"a key is neither old nor new: {dict(zip(keys, state))}")
        n_new = state.count("new")
        if state != ["new"] * n_new + ["old"] * (len(keys) - n_new):
            problems.append(f"the settings are not a prefix of the CONFIG_SETs: {state}")
        confirmed = sum(1 for r in replies if r["command"] == "CONFIG_SET" and "error" not in r["body"])
        if confirmed != len(replies):
            problems.append(f"a CONFIG_SET was refused: {replies}")
        if n_new < confirmed:
            problems.append(f"{confirmed} CONFIG_SETs confirmed to the host, {n_new} survive")
        return problems + _heater_problems(point)

    return Operation("config", template, requests, check, root)


def _die_after(fn: Callable[[], None]) -> None:
    """Run ``fn`` in a child that is then SIGKILLed (leaves what a killed daemon leaves: a WAL not checkpointed)."""
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child never returns
        try:
            fn()
            os.kill(os.getpid(), signal.SIGKILL)
        finally:
            os._exit(EXIT_CRASHED)
    _, status = os.waitpid(pid, 0)
    assert os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL, status


def startup_operation(root: Path, *, after_crash: bool) -> Operation:
    """The daemon's start-up, then one STATUS: on an empty state directory (first boot), or on what a
    killed daemon left (``after_crash``: a record only in the WAL, a staged upload, pointer and
    overrides temporaries, a bundle no pointer names).
    """
    from edge.storage.history import History

    template = Path(tempfile.mkdtemp(prefix=f"startup-{'crash' if after_crash else 'first'}-template-", dir=root))
    blobs = _variant_blobs(("A", "B")) if after_crash else {}
    sha: dict[str, str] = {}
    prior: dict[int, str] = {}
    if after_crash:
        store = open_model_store(template)
        sha = {tag: store.install(blobs[tag], hashlib.sha256(blobs[tag]).hexdigest(), len(blobs[tag])).sha256
               for tag in ("A", "B")}
        (template / "runtime.json").write_text(json.dumps({"heater.power_W": 2.0}))
        rec = {"status": "ok", "flags": [], "config": {}, "raw_t_s": [0.0, 0.1], "raw_T_C": [25.0, 25.5],
               "raw_q_W_m2": [0.0, 900.0]}

        def add_and_die() -> None:
            h = History(template / "history.db")
            h.add(rec)
            h.add(rec)

        _die_after(add_and_die)
        models = template / "models"
        shutil.copytree(models / "bundles" / sha["A"], models / "bundles" / ("c" * 64))  # moved in, never named
        (models / "tmp" / "upload-0123456789ab").mkdir()
        (models / "tmp" / "upload-0123456789ab" / "arrays.npz").write_bytes(b"partial")
        (models / ".current.tmp4242").write_bytes(b"half a poi")
        (template / ".runtime.json.tmp777").write_bytes(b"{\"heater.pow")
        problems, rows = _history_rows(Path(shutil.copytree(template, root / "startup-probe")) / "history.db")
        shutil.rmtree(root / "startup-probe")
        assert not problems and len(rows) == 2, problems
        prior = {mid: _row_digest(r) for mid, r in rows.items()}
        assert (template / "history.db-wal").stat().st_size > 0  # the records live in the WAL only

    def check(point: Path, replies: list[dict]) -> list[str]:
        problems, rows = _history_rows(point / "history.db") if (point / "history.db").exists() else ([], {})
        if set(rows) != set(prior) or any(_row_digest(rows[m]) != d for m, d in prior.items()):
            problems.append(f"history records changed across the start-up: {sorted(rows)} vs {sorted(prior)}")
        st = open_model_store(point)
        try:
            active = st.current()
            if after_crash and (st.source, active.sha256) != ("current", sha["B"]):
                problems.append(f"serves {st.source} {active.sha256[:12]}, not the installed model")
            if not after_crash and st.source != "factory":
                problems.append(f"first boot serves {st.source}")
        except Exception as e:  # noqa: BLE001
            problems.append(f"no model after the kill: {e}")
        leftovers = sorted(os.listdir(st.tmp_dir)) + [e for e in os.listdir(st.root) if e.startswith(".")]
        pointers = {p for p in (st._read_pointer(st.CURRENT), st._read_pointer(st.PREVIOUS)) if p}
        unreferenced = sorted(set(os.listdir(st.bundles_dir)) - pointers)
        if leftovers or unreferenced:
            problems.append(f"left after a second start-up: temporaries {leftovers}, unreferenced {unreferenced}")
        from edge.service.config import RuntimeOverrides
        from tests.support.daemons import sim_config

        ro = RuntimeOverrides(point / "runtime.json")
        ro.clean_temporaries()
        cfg = ro.load(sim_config(point))
        if ro.errors or cfg.heater.power_W != (2.0 if after_crash else sim_config(point).heater.power_W):
            problems.append(f"runtime overrides: {ro.errors}, power {cfg.heater.power_W}")
        if replies and replies[0]["body"].get("faults"):
            problems.append(f"the daemon started with faults: {replies[0]['body']['faults']}")
        return problems + _heater_problems(point)

    return Operation(f"startup-{'crash' if after_crash else 'first'}", template, [(Command.STATUS, {})], check,
                     startup=True)
