"""The model-upload session on its own: begin, chunks (with resends), commit, abort -- no daemon, no port."""

import hashlib
from types import SimpleNamespace

import pytest

from edge.model.store import InstallError
from edge.protocol.errors import CommandError, ErrorCode
from edge.service.upload import ModelUpload


class FakeStore:
    """Records what was installed; refuses a blob whose digest does not match."""

    def __init__(self, max_blob_bytes=1000):
        self.limits = SimpleNamespace(max_blob_bytes=max_blob_bytes)
        self.installed = []

    def install(self, blob, sha256, size, *, downgrade=None):
        if hashlib.sha256(blob).hexdigest() != sha256:
            raise InstallError("sha256 mismatch")
        self.installed.append(blob)
        return SimpleNamespace(sha256="b" * 64, model_version="v-test")


def _blob(n=100):
    data = bytes(range(256))[:n]
    return data, hashlib.sha256(data).hexdigest()


def test_begin_chunks_commit_installs_the_blob():
    store = FakeStore()
    up = ModelUpload(store, max_upload_bytes=1000)
    data, sha = _blob()
    assert up.progress() is None and not up.in_progress
    assert up.begin(len(data), sha, "v1") == {"size": len(data)}
    assert up.chunk(0, data[:60]) == {"received": 60}
    assert up.chunk(0, data[:60]) == {"received": 60}  # a resend of bytes already held
    assert up.progress() == {"received": 60, "size": len(data)}
    assert up.chunk(60, data[60:]) == {"received": len(data)}
    assert up.commit() == {"model_sha256": sha, "bundle_sha256": "b" * 64, "model_version": "v-test"}
    assert store.installed == [data] and not up.in_progress


def test_size_above_either_limit_is_rejected():
    data, sha = _blob()
    for store_limit, memory_limit in ((50, 1000), (1000, 50)):
        with pytest.raises(CommandError) as e:
            ModelUpload(FakeStore(store_limit), memory_limit).begin(len(data), sha)
        assert e.value.code == ErrorCode.MODEL_REJECTED


def test_chunks_out_of_order_or_past_the_end_are_refused():
    up = ModelUpload(FakeStore())
    data, sha = _blob()
    with pytest.raises(CommandError) as e:
        up.chunk(0, data)
    assert e.value.code == ErrorCode.BAD_STATE
    up.begin(len(data), sha)
    for offset, chunk in ((10, data[10:20]), (90, data[:20])):
        with pytest.raises(CommandError) as e:
            up.chunk(offset, chunk)
        assert e.value.code == ErrorCode.BAD_ARGUMENT
    assert up.progress() == {"received": 0, "size": len(data)}


def test_incomplete_commit_keeps_the_upload_and_a_refused_one_ends_it():
    store = FakeStore()
    up = ModelUpload(store)
    data, sha = _blob()
    up.begin(len(data), sha)
    up.chunk(0, data[:10])
    with pytest.raises(CommandError) as e:
        up.commit()
    assert e.value.code == ErrorCode.BAD_STATE and up.in_progress
    up.abort()
    assert not up.in_progress
    up.begin(len(data), "0" * 64)
    up.chunk(0, data)
    with pytest.raises(CommandError) as e:
        up.commit()
    assert e.value.code == ErrorCode.MODEL_REJECTED and not up.in_progress and store.installed == []


def test_sessions_refuse_foreign_and_stale_requests_without_disturbing_the_owner():
    store = FakeStore()
    up = ModelUpload(store)
    data, sha = _blob()
    up.begin(len(data), sha)
    s1 = up.session
    assert isinstance(s1, int) and 1 <= s1 <= 0xFFFFFFFF
    assert up.chunk(0, data[:40], s1, require_session=True) == {"received": 40}
    for call in (lambda: up.chunk(40, b"\xee" * 10, s1 ^ 1, require_session=True),
                 lambda: up.chunk(40, b"\xee" * 10, None, require_session=True),
                 lambda: up.commit(s1 ^ 1, require_session=True),
                 lambda: up.abort(s1 ^ 1, require_session=True)):
        with pytest.raises(CommandError) as e:
            call()
        assert e.value.code == ErrorCode.BAD_STATE
    assert up.progress() == {"received": 40, "size": len(data)} and up.session == s1
    up.begin(len(data), sha)  # a newer upload: s1 is stale now
    s2 = up.session
    assert s2 != s1
    with pytest.raises(CommandError) as e:
        up.chunk(0, data, s1, require_session=True)
    assert e.value.code == ErrorCode.BAD_STATE
    assert up.chunk(0, data, s2, require_session=True) == {"received": len(data)}
    assert up.commit(s2, require_session=True)["model_sha256"] == sha
    assert up.session is None and up.abort(s2, require_session=True) == {}  # nothing left: a no-op
