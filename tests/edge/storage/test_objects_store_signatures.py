"""A stored set's signer is the signer of the bytes stored (ISSUE #35 §9), at every cut of an install."""

import hashlib

import pytest

from edge.security.keys import signature_document
from edge.security.policy import UpdatePolicy
from edge.service.objects import parse_object_set
from edge.storage import durable
from edge.storage.objects_store import ObjectSetStore, ObjectStoreError

# Signed sets name their version (an older signed set is refused: ISSUE #35 §2): B is newer than A.
A = b"# created_utc: 2026-01-01T00:00:00Z\nname,class,e_W_s05_m2K\ncup,ceramic,1400\nsponge,foam,60\n"
B = b"# created_utc: 2026-02-01T00:00:00Z\nname,class,e_W_s05_m2K\ndesk,wood,400\n"


def sha(b):
    return hashlib.sha256(b).hexdigest()


def store(tmp_path, policy):
    return ObjectSetStore(tmp_path / "objects", parse_object_set, policy=policy)


@pytest.mark.parametrize("cut_at", range(4))
def test_a_cut_install_never_names_the_wrong_signer(tmp_path, keys, monkeypatch, cut_at):
    k1, k2, policy = keys
    s = store(tmp_path, policy)
    s.install("kitchen", A, sha(A), signature=signature_document(k1, A))
    assert s.signed_by("kitchen") == k1.key_id
    real, n = durable.replace, {"i": 0}

    def replace(src, dst):  # the cut_at-th durable rename of the second install is cut by a power loss
        if n["i"] == cut_at:
            raise OSError("power cut")
        n["i"] += 1
        real(src, dst)

    monkeypatch.setattr(durable, "replace", replace)
    try:
        s.install("kitchen", B, sha(B), signature=signature_document(k2, B))
    except ObjectStoreError:
        pass
    monkeypatch.undo()
    s2 = store(tmp_path, policy)  # restart
    stored = (tmp_path / "objects" / "sets" / "kitchen.csv").read_bytes()
    assert stored in (A, B)
    assert s2.signed_by("kitchen") == (k1 if stored == A else k2).key_id
    assert [x["signed_by"] for x in s2.listing()] == [(k1 if stored == A else k2).key_id]


def test_an_unsigned_replacement_drops_the_old_signer_and_remove_drops_every_signature(tmp_path, keys):
    k1, _, _ = keys
    s = store(tmp_path, UpdatePolicy(keys[2].trusted_keys_dir, allow_unsigned=True))
    s.install("kitchen", A, sha(A), signature=signature_document(k1, A))
    s.install("kitchen", B, sha(B))
    assert s.signed_by("kitchen") is None
    s.install("kitchen", A, sha(A), signature=signature_document(k1, A))
    s.remove("kitchen")
    assert not any(p.suffix == ".sig" for p in (tmp_path / "objects" / "sets").iterdir())


def test_an_earlier_stores_signature_is_kept_only_if_it_signs_the_stored_bytes(tmp_path, keys):
    k1, k2, policy = keys
    sets = tmp_path / "objects" / "sets"
    sets.mkdir(parents=True)
    (sets / "good.csv").write_bytes(A)
    (sets / "good.sig").write_bytes(signature_document(k1, A))
    (sets / "stale.csv").write_bytes(B)
    (sets / "stale.sig").write_bytes(signature_document(k2, A))  # left by a cut install: signs other bytes
    s = store(tmp_path, policy)
    assert s.signed_by("good") == k1.key_id and s.signed_by("stale") is None
    assert sorted(p.name for p in sets.iterdir()) == sorted(["good.csv", f"good.{sha(A)}.sig", "stale.csv"])
