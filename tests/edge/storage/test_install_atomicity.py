"""Installs atomic together with their signatures (ISSUE #35 §9), killed before every file-system step.

Each install is run once to count its steps (every mutating ``os`` call: create, write, fsync,
replace, rename, unlink, mkdir), then once per step with the process "killed" right before it
(an exception no store code catches, so nothing after it runs). A restart then opens the store
fresh and checks: the data in use parses, its signature matches its bytes (``signed_by`` names the
signer of exactly those bytes), and the install happened completely as asked (stored and active
when activation was asked, its signer recorded) or not at all. The fork-and-SIGKILL version of the
same through the daemon is tests/edge/service/test_kill_points.py.
"""

from __future__ import annotations

import hashlib
import json
import os

import pytest

from edge.calibration.model import MAX_BYTES, ProbeCalibration
from edge.security.keys import signature_document
from edge.service.objects import parse_object_set
from edge.storage.calibration_store import CalibrationStore
from edge.storage.objects_store import ObjectSetStore
from tests.support.calibrations import DEVICE_ID, sample_calibration

# Signed sets name their version (an older signed set is refused: ISSUE #35 §2): B is newer than A.
A = b"# created_utc: 2026-01-01T00:00:00Z\nname,class,e_W_s05_m2K\ncup,ceramic,1400\nsponge,foam,60\n"
B = b"# created_utc: 2026-02-01T00:00:00Z\nname,class,e_W_s05_m2K\ndesk,wood,400\n"
_MUTATING = ("open", "write", "fsync", "replace", "rename", "unlink", "mkdir", "rmdir")


class _Killed(BaseException):
    """The process died here (a BaseException: the stores' ``except OSError`` does not see it)."""


def sha(b: bytes) -> str:
    return hashlib.sha256(b).hexdigest()


def _run_killed_at(monkeypatch, n: int | None, fn) -> int:
    """Run ``fn`` with every mutating os call counted; raise :class:`_Killed` before call ``n``. Returns the count."""
    count = {"i": 0}
    for name in _MUTATING:
        real = getattr(os, name)

        def wrapper(*args, _real=real, _name=name, **kw):
            if _name == "open" and not (args[1] if len(args) > 1 else kw.get("flags", 0)) & os.O_CREAT:
                return _real(*args, **kw)
            count["i"] += 1
            if count["i"] == n:
                raise _Killed()
            return _real(*args, **kw)

        monkeypatch.setattr(os, name, wrapper)
    try:
        fn()
    except _Killed:
        pass
    finally:
        monkeypatch.undo()
    return count["i"]


def _every_point(tmp_path, monkeypatch, prepare, install, check) -> int:
    """Count the install's steps, then kill before each (and after the last); ``check`` after a restart."""
    base = tmp_path / "dry"
    prepare(base)
    steps = _run_killed_at(monkeypatch, None, lambda: install(base))
    assert steps >= 6
    for n in range(1, steps + 2):
        root = tmp_path / f"k{n}"
        prepare(root)
        _run_killed_at(monkeypatch, n, lambda: install(root))
        check(root, n)
    return steps


# ---------------------------------------------------------------------------------------------- object sets

def _objects(root, policy):
    return ObjectSetStore(root / "objects", parse_object_set, policy=policy)


@pytest.mark.slow  # a kill-point sweep: the install restarted once per file-system step
@pytest.mark.parametrize("name", ["kitchen", "bench"], ids=["replace-the-active-set", "new-set-activated"])
def test_an_object_set_install_is_all_or_nothing_with_its_signature(tmp_path, keys, monkeypatch, name):
    k1, k2, policy = keys

    def prepare(root):
        s = _objects(root, policy)
        s.install("kitchen", A, sha(A), signature=signature_document(k1, A))
        s.install("spare", A, sha(A), activate=False, signature=signature_document(k1, A))
        s.select("kitchen")

    def install(root):
        _objects(root, policy).install(name, B, sha(B), activate=True, signature=signature_document(k2, B))

    outcomes = set()

    def check(root, n):
        s = _objects(root, policy)  # the restart: finishes or forgets the cut install
        act = s.active()
        assert s.error is None and act is not None, (n, s.error)
        new = act.name == name and act.sha256 == sha(B)
        if new:
            assert s.signed_by(name) == k2.key_id, n
        else:  # not at all: the old set active, the new name (if new) absent, the old signers
            assert act.name == "kitchen" and act.sha256 == sha(A), n
            assert s.signed_by("kitchen") == k1.key_id, n
            assert name == "kitchen" or name not in s.names(), (n, s.names())
        assert s.signed_by("spare") == k1.key_id
        listing = {x["name"]: x for x in s.listing()}
        assert all("error" not in x for x in listing.values()), listing
        for x in listing.values():  # every listed signer signed exactly the bytes listed
            held = (root / "objects" / "sets" / f"{x['name']}.csv").read_bytes()
            assert x["signed_by"] == (k2 if held == B else k1).key_id, (n, x)
        leftovers = [p.name for p in (root / "objects").rglob("*") if ".tmp" in p.name or p.name == "pending"]
        sigs = sorted(p.name for p in (root / "objects" / "sets").glob("*.sig"))
        assert not leftovers and len(sigs) == len(listing), (n, leftovers, sigs)
        outcomes.add(new)

    steps = _every_point(tmp_path, monkeypatch, prepare, install, check)
    assert outcomes == {False, True}, steps  # both ends were reached: the points span the commit


def test_an_unfinished_install_is_completed_and_activated_at_start_up(tmp_path, keys):
    """The commit point: the bytes renamed in, killed before the pointer: the restart activates them."""
    k1, k2, policy = keys
    s = _objects(tmp_path, policy)
    s.install("kitchen", A, sha(A), signature=signature_document(k1, A))
    objects = tmp_path / "objects"
    (objects / "sets" / f"bench.{sha(B)}.sig").write_bytes(signature_document(k2, B))
    (objects / "pending").write_text(json.dumps({"name": "bench", "sha256": sha(B), "activate": True}))
    (objects / "sets" / "bench.csv").write_bytes(B)
    s2 = _objects(tmp_path, policy)
    assert s2.active().name == "bench" and s2.signed_by("bench") == k2.key_id
    assert not (objects / "pending").exists()


def test_a_pending_install_without_its_bytes_is_forgotten_with_its_signature(tmp_path, keys):
    k1, k2, policy = keys
    s = _objects(tmp_path, policy)
    s.install("kitchen", A, sha(A), signature=signature_document(k1, A))
    objects = tmp_path / "objects"
    (objects / "sets" / f"kitchen.{sha(B)}.sig").write_bytes(signature_document(k2, B))
    (objects / "pending").write_text(json.dumps({"name": "kitchen", "sha256": sha(B), "activate": True}))
    s2 = _objects(tmp_path, policy)
    assert s2.active().sha256 == sha(A) and s2.signed_by("kitchen") == k1.key_id
    assert sorted(p.name for p in (objects / "sets").iterdir()) == sorted(["kitchen.csv", f"kitchen.{sha(A)}.sig"])
    assert not (objects / "pending").exists()
    (objects / "pending").write_text("{not json")  # a damaged record is dropped, the store opens
    assert _objects(tmp_path, policy).active().sha256 == sha(A) and not (objects / "pending").exists()


# ---------------------------------------------------------------------------------------------- calibrations

def _calibrations(root, policy):
    return CalibrationStore(root / "cal", "paper", policy, parse=ProbeCalibration.from_json, max_bytes=MAX_BYTES,
                            device_id=lambda: DEVICE_ID)


@pytest.mark.slow  # a kill-point sweep, as above
def test_a_calibration_install_is_all_or_nothing_with_its_signature(tmp_path, keys, monkeypatch):
    k1, k2, policy = keys
    # The replacement is newer (a calibration not newer than the installed one is refused) and both
    # name this device (a strict device takes only calibrations bound to it).
    old = sample_calibration(device_id=DEVICE_ID)
    new = sample_calibration(flux_scale=0.95, created_utc="2026-11-24T00:00:00Z", device_id=DEVICE_ID)
    old_b, new_b = old.to_json().encode(), new.to_json().encode()

    def prepare(root):
        _calibrations(root, policy).install(old_b, signature_document(k1, old_b))

    def install(root):
        _calibrations(root, policy).install(new_b, signature_document(k2, new_b))

    outcomes = set()

    def check(root, n):
        st = _calibrations(root, policy)
        cur = st.current()
        assert cur in (old, new), n
        assert st.signed_by() == (k2 if cur == new else k1).key_id, n
        names = sorted(p.name for p in (root / "cal").iterdir())
        held = sha((root / "cal" / "calibration.json").read_bytes())
        assert names == sorted(["calibration.json", f"calibration.{held}.sig"]), (n, names)
        outcomes.add(cur == new)

    steps = _every_point(tmp_path, monkeypatch, prepare, install, check)
    assert outcomes == {False, True}, steps


def test_an_earlier_calibration_signature_is_kept_only_if_it_signs_the_stored_bytes(tmp_path, keys):
    k1, k2, policy = keys
    blob = sample_calibration().to_json().encode()
    for tag, signer, signed in (("good", k1, blob), ("stale", k2, blob + b" ")):
        d = tmp_path / tag / "cal"
        d.mkdir(parents=True)
        (d / "calibration.json").write_bytes(blob)
        (d / "calibration.sig").write_bytes(signature_document(signer, signed))
        st = _calibrations(tmp_path / tag, policy)
        assert st.signed_by() == (k1.key_id if tag == "good" else None)
        assert sorted(p.name for p in d.iterdir()) == sorted(["calibration.json"]
                                                             + ([f"calibration.{sha(blob)}.sig"] if tag == "good"
                                                                else []))
