"""The object-set store on its own: verification before any write, atomic replacement, crash leftovers."""

import hashlib

from pathlib import Path

import pytest

from edge.security.policy import UpdatePolicy
from edge.service.objects import parse_object_set
from edge.storage import durable
from edge.storage.objects_store import ObjectSetStore, ObjectStoreError, UploadRefused, verify_upload

A = b"name,class,e_W_s05_m2K\ncup,ceramic,1400\nsponge,foam,60\n"
B = b"name,class,e_W_s05_m2K\ndesk,wood,400\n"


def sha(b):
    return hashlib.sha256(b).hexdigest()


#: A development device's policy: these tests are about storage, not who signed (test_objects_signed.py).
DEV = UpdatePolicy(allow_unsigned=True)


def store(tmp_path, **kw):
    kw.setdefault("policy", DEV)
    return ObjectSetStore(tmp_path / "objects", parse_object_set, **kw)


def test_verify_upload_checks_size_digest_text_and_csv():
    assert len(verify_upload(A, sha(A), len(A), name="a", parse=parse_object_set, policy=DEV)) == 2
    cases = [((A, sha(A), len(A)), dict(max_bytes=10), "above the limit"),
             ((A, sha(A), len(A) + 1), {}, "announced"),
             ((A, "0" * 64, len(A)), {}, "sha256 mismatch"),
             ((b"\xff\xfe", sha(b"\xff\xfe"), 2), {}, "UTF-8"),
             ((b"name,class\n", sha(b"name,class\n"), 11), {}, "line 1")]
    for (blob, digest, size), kw, needle in cases:
        with pytest.raises(UploadRefused, match=needle):
            verify_upload(blob, digest, size, name="a", parse=parse_object_set, policy=DEV, **kw)


def test_install_select_remove_and_reload(tmp_path):
    s = store(tmp_path)
    assert s.active() is None and s.names() == []
    s.install("a", A, sha(A))
    s.install("b", B, sha(B), activate=False)
    assert s.active().name == "a" and s.names() == ["a", "b"]
    assert store(tmp_path).active().name == "a"  # a new process reads the pointer
    s.select("b")
    assert store(tmp_path).active().name == "b"
    assert s.remove("b") is True and s.active() is None and store(tmp_path).active() is None
    assert s.remove("a") is False
    with pytest.raises(ObjectStoreError):
        s.remove("a")


def test_a_refused_upload_writes_nothing(tmp_path):
    s = store(tmp_path)
    s.install("a", A, sha(A))
    before = sorted(p.name for p in (tmp_path / "objects").rglob("*"))
    with pytest.raises(UploadRefused):
        s.install("a", b"name,class\n", sha(b"name,class\n"))
    assert sorted(p.name for p in (tmp_path / "objects").rglob("*")) == before
    assert (tmp_path / "objects" / "sets" / "a.csv").read_bytes() == A


def test_store_full_and_reserved_names(tmp_path):
    s = store(tmp_path, max_sets=2)
    s.install("a", A, sha(A))
    s.install("b", B, sha(B))
    with pytest.raises(ObjectStoreError, match="remove one"):
        s.install("c", B, sha(B))
    s.install("a", B, sha(B))  # replacing one is fine when full
    for bad in ("library", "a/b", "", ".x"):
        with pytest.raises(UploadRefused):
            s.install(bad, B, sha(B))


def test_a_crash_mid_write_leaves_the_old_set_and_no_temporaries(tmp_path, monkeypatch):
    s = store(tmp_path)
    s.install("a", A, sha(A))

    real = durable.replace

    def cut(src, dst):  # power cut before the set's rename: its temporary is written, the name is not
        if Path(dst).parent.name != "sets":
            return real(src, dst)  # the install's record of itself goes first
        raise OSError("power cut")

    monkeypatch.setattr(durable, "replace", cut)
    with pytest.raises(ObjectStoreError, match="power cut"):
        s.install("a", B, sha(B))
    monkeypatch.undo()
    assert any(".tmp" in p.name for p in (tmp_path / "objects" / "sets").iterdir())
    s2 = store(tmp_path)  # restart
    assert s2.active().name == "a" and s2.active().sha256 == sha(A)
    assert not any(".tmp" in p.name for p in (tmp_path / "objects").rglob("*"))
