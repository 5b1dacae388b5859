"""Object sets are versioned like calibrations (ISSUE #35 §2): an older signed set is not re-installed."""

import hashlib
from datetime import datetime, timezone

import pytest

from edge.security.keys import signature_document
from edge.security.policy import UpdatePolicy
from edge.service.objects import parse_object_set
from edge.storage.objects_store import ObjectSetStore, UploadRefused, set_created_utc
from host.objects import stamp_version

ROWS = b"name,class,e_W_s05_m2K\ncup,ceramic,1400\n"
OLD = b"# created_utc: 2026-01-01T00:00:00Z\n" + ROWS
NEW = b"# a comment first\n# created_utc: 2026-02-01T00:00:00Z\n" + ROWS.replace(b"1400", b"1450")
CLOCK = datetime(2026, 11, 27, tzinfo=timezone.utc)


def sha(b):
    return hashlib.sha256(b).hexdigest()


def store(tmp_path, policy):
    return ObjectSetStore(tmp_path / "objects", parse_object_set, policy=policy, now=lambda: CLOCK)


def install(s, key, name, blob, **kw):
    return s.install(name, blob, sha(blob), signature=None if key is None else signature_document(key, blob), **kw)


def test_an_older_signed_set_is_refused_after_a_newer_under_any_name_and_after_a_removal(tmp_path, keys):
    k1, k2, policy = keys
    s = store(tmp_path, policy)
    install(s, k1, "kitchen", OLD)
    install(s, k2, "kitchen", NEW)
    for name in ("kitchen", "other"):   # the replay under the same name, or a fresh one to select later
        with pytest.raises(UploadRefused, match=r"created 2026-01-01T00:00:00Z, not newer than the installed one "
                                                r"\(2026-02-01T00:00:00Z\); an older object set is not re-installed"):
            install(s, k1, name, OLD)
    assert s.active().sha256 == sha(NEW) and s.names() == ["kitchen"]
    install(s, k2, "kitchen", NEW)                  # the newest bytes again: no version change
    install(s, k2, "spare", NEW, activate=False)    # ... under another name too
    s.remove("kitchen")
    s.remove("spare")
    s2 = store(tmp_path, policy)                    # the floor survives the removal and a restart
    with pytest.raises(UploadRefused, match="not newer than the installed one"):
        install(s2, k1, "kitchen", OLD)
    assert s2.version_floor() == ("2026-02-01T00:00:00Z", sha(NEW))


def test_a_signed_set_names_its_version_in_the_past_and_unsigned_sets_are_not_ordered(tmp_path, keys):
    k1, _, _ = keys
    s = store(tmp_path, UpdatePolicy(keys[2].trusted_keys_dir, allow_unsigned=True))
    with pytest.raises(UploadRefused, match="a signed set names its version in a line '# created_utc: "):
        install(s, k1, "kitchen", ROWS)
    ahead = b"# created_utc: 2036-01-01T00:00:00Z\n" + ROWS
    with pytest.raises(UploadRefused, match="created_utc 2036-01-01T00:00:00Z is in the future"):
        install(s, k1, "kitchen", ahead)
    with pytest.raises(UploadRefused, match="created_utc '2026-1-1' is not YYYY-MM-DDTHH:MM:SSZ"):
        install(s, k1, "kitchen", b"# created_utc: 2026-1-1\n" + ROWS)
    assert s.names() == [] and s.version_floor() is None
    install(s, k1, "kitchen", NEW)
    # Unsigned (a development device): the sender dates it as it likes, so no floor applies.
    assert install(s, None, "kitchen", OLD).sha256 == sha(OLD)
    assert install(s, None, "plain", ROWS).sha256 == sha(ROWS)
    assert s.version_floor() == ("2026-02-01T00:00:00Z", sha(NEW))


def test_the_version_line_is_read_before_the_header_and_the_host_stamps_unversioned_sets():
    assert set_created_utc(OLD) == "2026-01-01T00:00:00Z" and set_created_utc(NEW) == "2026-02-01T00:00:00Z"
    assert set_created_utc(ROWS + b"# created_utc: 2026-01-01T00:00:00Z\n") is None   # after the header: a row
    assert stamp_version(OLD) == OLD
    stamped = stamp_version(b"\xef\xbb\xbf" + ROWS)
    assert stamped.endswith(b"\n" + ROWS) and b"\xef\xbb\xbf" not in stamped
    assert datetime.strptime(set_created_utc(stamped), "%Y-%m-%dT%H:%M:%SZ").year >= 2026
    assert len(parse_object_set(stamped.decode(), "x")) == 1
