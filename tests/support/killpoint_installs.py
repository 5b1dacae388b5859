"""Kill points of the signed installs: CALIBRATION_SET, and OBJECTS_BEGIN/CHUNK/COMMIT with activation.

Each operation's template already holds an install signed by one key; the operation installs new
bytes signed by another. After a kill before any step and a restart (the stores opened fresh, as
at the daemon's start), :class:`tests.support.killpoint_runner.Operation.check` asks (ISSUE #35 §9):

* the data in use is whole (it parses; the active object set loads);
* its signature matches its bytes: ``signed_by`` names the key that signed exactly the bytes in use
  (the old key beside the old bytes, the new key beside the new ones), for every stored set;
* the install is all or nothing: either the old state, or the new bytes stored *and* active (the
  upload asked for activation) with their signer; the new state once the host was told;
* nothing stray survives start-up: no temporaries, no pending install record, no signature of
  bytes no set holds.

The overview of the harness is :mod:`tests.support.killpoints`.
"""

from __future__ import annotations

import hashlib
import json
import tempfile
from pathlib import Path

from edge.protocol.commands import Command
from tests.support.killpoint_runner import Operation, heater_line

__all__ = ["calibration_operation", "objects_operation", "OBJECTS_CHUNK_BYTES"]

#: Chunk size of the object-set upload (the set is sent in several chunks).
OBJECTS_CHUNK_BYTES = 512


def _keys(template: Path) -> tuple:
    """Two trusted signing keys in the template's ``trusted_keys`` (sim_config trusts that directory)."""
    from edge.security.keys import SecretKey

    d = template / "trusted_keys"
    d.mkdir()
    keys = SecretKey.generate(), SecretKey.generate()
    for k in keys:
        (d / f"{k.key_id}.json").write_text(json.dumps(k.public_key().document()))
    return keys


def _policy(point: Path):
    from edge.security.policy import UpdatePolicy

    # The device's own rule would accept unsigned bytes too (a simulated probe): signatures given are
    # still verified against the trusted keys, which is what signed_by reports.
    return UpdatePolicy(trusted_keys_dir=str(point / "trusted_keys"), allow_unsigned=True)


def _heater_problems(point: Path) -> list[str]:
    line = heater_line(point)
    if line is None:
        return ["the enable line was never mirrored"]
    return [] if line["level"] == 0 else [f"heater enable line high after the kill: {line}"]


def _confirmed(replies: list[dict], command: str) -> list[dict]:
    return [r["body"] for r in replies if r["command"] == command]


def calibration_operation(root: Path) -> Operation:
    """One signed CALIBRATION_SET over a calibration signed by another key."""
    from edge.calibration.model import MAX_BYTES, ProbeCalibration
    from edge.security.keys import signature_document
    from edge.storage.calibration_store import CalibrationStore
    from edge.storage.history import History
    from tests.support.calibrations import sample_calibration

    template = Path(tempfile.mkdtemp(prefix="calset-template-", dir=root))
    History(template / "history.db").close()
    k_old, k_new = _keys(template)
    # The new one is newer: a calibration not newer than the installed one is refused (ISSUE #35 §2).
    old, new = sample_calibration(flux_scale=0.97), sample_calibration(flux_scale=0.95, created_utc="2026-11-24T00:00:00Z")
    old_b, new_b = old.to_json_compact().encode(), new.to_json_compact().encode()

    def store(point: Path) -> CalibrationStore:
        return CalibrationStore(point / "calibration", "paper", _policy(point), parse=ProbeCalibration.from_json,
                                max_bytes=MAX_BYTES)

    store(template).install(old_b, signature_document(k_old, old_b))
    requests = [(Command.CALIBRATION_SET, {"calibration": new_b.decode(),
                                           "signature": signature_document(k_new, new_b).decode()})]

    def check(point: Path, replies: list[dict]) -> list[str]:
        problems: list[str] = []
        answers = _confirmed(replies, "CALIBRATION_SET")
        if answers and "sha256" not in answers[0]:
            return [f"CALIBRATION_SET refused: {answers[0]}"]
        st = store(point)  # start-up cleaning happens here, as in the daemon
        try:
            cur = st.current()
        except Exception as e:  # noqa: BLE001 - a calibration that cannot be read is what we look for
            return [f"the calibration in use is damaged after the kill: {e}"] + _heater_problems(point)
        if cur not in (old, new):
            problems.append(f"the calibration in use is neither the old nor the new one: {cur}")
        want = k_new if cur == new else k_old
        if st.signed_by() != want.key_id:
            problems.append(f"signed_by {st.signed_by()} beside the {'new' if cur == new else 'old'} bytes, "
                            f"signed by {want.key_id}")
        if answers and cur != new:
            problems.append("the calibration was confirmed to the host but the old one is in use")
        names = sorted(p.name for p in (point / "calibration").iterdir())
        held = hashlib.sha256((point / "calibration" / "calibration.json").read_bytes()).hexdigest()
        if names != sorted(["calibration.json", f"calibration.{held}.sig"]):
            problems.append(f"left in the store after start-up: {names}")
        return problems + _heater_problems(point)

    return Operation("calibration", template, requests, check, root)


_CLASSES = ("foam", "wood", "polymer", "rubber", "glass", "ceramic", "stone", "metal")


def _csv(rows: int, tag: str, created_utc: str) -> bytes:
    # Signed sets name their version; the new one is newer (an older signed set is refused: ISSUE #35 §2).
    lines = [f"# created_utc: {created_utc}", "name,class,e_W_s05_m2K"]
    lines += [f"{tag}-object-{i:03d},{_CLASSES[i % len(_CLASSES)]},{300 + 17 * i}" for i in range(rows)]
    return ("\n".join(lines) + "\n").encode()


def objects_operation(root: Path, name: str = "bench") -> Operation:
    """A signed object-set upload with activation (OBJECTS_BEGIN, OBJECTS_CHUNKs, OBJECTS_COMMIT).

    The store holds ``kitchen`` (active) and ``spare``, both signed by one key; the upload of set
    ``name`` (``"bench"``: a new set; ``"kitchen"``: replacing the active one) is signed by another.
    """
    from edge.security.keys import signature_document
    from edge.service.objects import parse_object_set
    from edge.storage.history import History
    from edge.storage.objects_store import ObjectSetStore

    template = Path(tempfile.mkdtemp(prefix=f"objects-{name}-template-", dir=root))
    History(template / "history.db").close()
    k_old, k_new = _keys(template)
    old, blob = _csv(12, "old", "2026-01-01T00:00:00Z"), _csv(60, "new", "2026-02-01T00:00:00Z")
    sha_old, sha_new = hashlib.sha256(old).hexdigest(), hashlib.sha256(blob).hexdigest()

    def store(point: Path) -> ObjectSetStore:
        return ObjectSetStore(point / "objects", parse_object_set, policy=_policy(point))

    s = store(template)
    s.install("spare", old, sha_old, activate=False, signature=signature_document(k_old, old))
    s.install("kitchen", old, sha_old, activate=True, signature=signature_document(k_old, old))
    requests: list[tuple[Command, dict]] = [(Command.OBJECTS_BEGIN, {
        "name": name, "size": len(blob), "sha256": sha_new, "activate": True,
        "signature": signature_document(k_new, blob).decode()})]
    for off in range(0, len(blob), OBJECTS_CHUNK_BYTES):
        requests.append((Command.OBJECTS_CHUNK, {"offset": off, "data": blob[off:off + OBJECTS_CHUNK_BYTES]}))
    requests.append((Command.OBJECTS_COMMIT, {}))

    def check(point: Path, replies: list[dict]) -> list[str]:
        problems: list[str] = []
        answers = _confirmed(replies, "OBJECTS_COMMIT")
        if answers and "sha256" not in answers[0]:
            return [f"OBJECTS_COMMIT refused: {answers[0]}"]
        st = store(point)  # finishes or forgets a cut install, as at the daemon's start
        act = st.active()
        if act is None or st.error:
            return [f"no stored set active after the kill: {st.error}"] + _heater_problems(point)
        new = (act.name, act.sha256) == (name, sha_new)
        if not new and (act.name, act.sha256) != ("kitchen", sha_old):
            problems.append(f"active set {act.name} ({act.sha256[:12]}) is neither the old nor the new state")
        if not new and name != "kitchen" and name in st.names():
            problems.append(f"set {name!r} stored but not active: the install was half done")
        if answers and not new:
            problems.append("the upload was confirmed to the host but the new set is not active")
        for row in st.listing():
            if "error" in row:
                problems.append(f"stored set {row['name']} does not load: {row['error']}")
                continue
            want = k_new if row["sha256"] == sha_new else k_old
            if row["signed_by"] != want.key_id:
                problems.append(f"set {row['name']}: signed_by {row['signed_by']}, its bytes were signed by "
                                f"{want.key_id}")
        objects = point / "objects"
        stray = [p.name for p in objects.rglob("*") if ".tmp" in p.name or p.name == "pending"]
        sigs = sorted(p.name for p in (objects / "sets").glob("*.sig"))
        if stray or len(sigs) != len(st.names()):
            problems.append(f"left after start-up: temporaries {stray}, signatures {sigs} for sets {st.names()}")
        return problems + _heater_problems(point)

    return Operation(f"objects-{name}", template, requests, check, root)
