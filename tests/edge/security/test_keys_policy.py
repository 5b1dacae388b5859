"""Key and signature documents parsed strictly; the update policy's decisions without a store."""

from __future__ import annotations

import json

import pytest

from edge.security.keys import (
    KeyFileError, PublicKey, SecretKey, downgrade_document, load_trusted_keys, parse_key, parse_signature, signature_document,
)
from edge.security.policy import Authentication, UpdatePolicy, UpdateRefused


@pytest.fixture(scope="module")
def key():
    return SecretKey.generate("k")


def test_documents_round_trip(key):
    assert parse_key(json.dumps(key.document())) == SecretKey(key.secret, key.public, key.key_id)
    assert parse_key(json.dumps(key.public_key().document())) == PublicKey(key.public, key.key_id)
    kid, sig = parse_signature(signature_document(key, b"m"))
    assert kid == key.key_id and len(sig) == 64
    assert key.secret.hex() not in repr(key)  # never print the secret


@pytest.mark.parametrize("mutate, message", [
    (lambda d: d.update(kind="rsa"), "'kind' must be"),
    (lambda d: d.update(key_id="0" * 16), "does not match its public key"),
    (lambda d: d.update(public_hex="AB" * 32), "'public_hex' must be 64 lowercase hex digits"),
    (lambda d: d.update(secret_hex="00" * 32), "'secret_hex' does not derive 'public_hex'"),
])
def test_malformed_or_inconsistent_key_files_are_refused(key, mutate, message):
    d = key.document()
    mutate(d)
    with pytest.raises(KeyFileError, match=message):
        parse_key(json.dumps(d), "k.json")


def test_public_key_file_with_a_secret_is_refused(key):
    d = key.document()
    d["kind"] = "thermotouch-ed25519-public"
    with pytest.raises(KeyFileError, match="must not hold 'secret_hex'"):
        parse_key(json.dumps(d))


def test_trusted_dir_takes_public_keys_and_reports_the_rest(tmp_path, key):
    other = SecretKey.generate()
    (tmp_path / "a.public.json").write_text(json.dumps(key.public_key().document()))
    (tmp_path / "b.secret.json").write_text(json.dumps(other.document()))
    (tmp_path / "c.json").write_text("not json")
    keys, skipped = load_trusted_keys(tmp_path)
    assert set(keys) == {key.key_id, other.key_id}
    assert any("keep secrets off the device" in s for s in skipped) and any("not JSON" in s for s in skipped)
    assert load_trusted_keys(tmp_path / "missing")[0] == {}


def test_policy_decisions(tmp_path, key):
    (tmp_path / "k.public.json").write_text(json.dumps(key.public_key().document()))
    strict = UpdatePolicy(str(tmp_path), allow_unsigned=False)
    dev = UpdatePolicy(str(tmp_path), allow_unsigned=True)
    m = b'{"created_utc": "2025-01-01T00:00:00Z"}'
    assert strict.authenticate(m, signature_document(key, m)) == Authentication(key.key_id)
    with pytest.raises(UpdateRefused, match="unsigned update refused"):
        strict.authenticate(m, None)
    assert dev.authenticate(m, None) == Authentication(None)
    with pytest.raises(UpdateRefused, match="bad signature"):  # a signature is checked even where unsigned is allowed
        dev.authenticate(m + b" ", signature_document(key, m))
    with pytest.raises(UpdateRefused, match="untrusted key"):
        UpdatePolicy(None).authenticate(m, signature_document(key, m))


def test_version_floor(key, tmp_path):
    (tmp_path / "k.public.json").write_text(json.dumps(key.public_key().document()))
    policy = UpdatePolicy(str(tmp_path))
    signed, unsigned = Authentication(key.key_id), Authentication(None)
    old, new = {"created_utc": "2024-01-01T00:00:00Z"}, {"created_utc": "2025-01-01T00:00:00Z"}
    n, o = "a" * 64, "b" * 64
    policy.check_newer(new, n, old, o, auth=signed)
    for same_time in (old, dict(old)):
        with pytest.raises(UpdateRefused, match="downgrade refused"):
            policy.check_newer(same_time, n, old, o, auth=signed)
    policy.check_newer(old, n, new, o, auth=signed, downgrade=downgrade_document(key, n, o))
    policy.check_newer(old, o, new, o, auth=signed)  # the running bundle again
    policy.check_newer(old, n, new, o, auth=unsigned)  # no authentication, no floor
    policy.check_newer(old, n, None, None, auth=signed)  # nothing active
    with pytest.raises(UpdateRefused, match="not YYYY-MM-DDTHH:MM:SSZ"):
        policy.check_newer({"created_utc": "yesterday"}, n, old, o, auth=signed)


def test_a_downgrade_needs_an_authorisation_for_exactly_this_pair_by_a_trusted_key(key, tmp_path):
    """ISSUE #35 §1: nobody on the link can ask for a rollback; a signed one is spent once another model runs."""
    (tmp_path / "k.public.json").write_text(json.dumps(key.public_key().document()))
    policy = UpdatePolicy(str(tmp_path))
    signed = Authentication(key.key_id)
    old, new = {"created_utc": "2024-01-01T00:00:00Z"}, {"created_utc": "2025-01-01T00:00:00Z"}
    n, o, other = "a" * 64, "b" * 64, "c" * 64
    with pytest.raises(UpdateRefused, match="downgrade refused"):
        policy.check_newer(old, n, new, o, auth=signed)
    with pytest.raises(UpdateRefused, match="it allows aaaaaaaaaaaa... over cccccccccccc..., not .* over the active bbb"):
        policy.check_newer(old, n, new, o, auth=signed, downgrade=downgrade_document(key, n, other))
    with pytest.raises(UpdateRefused, match="allows cccccccccccc"):
        policy.check_newer(old, n, new, o, auth=signed, downgrade=downgrade_document(key, other, o))
    stranger = SecretKey.generate()
    with pytest.raises(UpdateRefused, match=f"downgrade authorisation by untrusted key {stranger.key_id} refused"):
        policy.check_newer(old, n, new, o, auth=signed, downgrade=downgrade_document(stranger, n, o))
    doc = json.loads(downgrade_document(key, n, o))
    doc["from_sha256"] = other  # re-addressed by hand: the signature no longer covers it
    with pytest.raises(UpdateRefused, match="bad downgrade authorisation"):
        policy.check_newer(old, n, new, other, auth=signed, downgrade=json.dumps(doc))
    for junk in (b"{}", b"[1]", b"not json", json.dumps({**doc, "kind": "thermotouch-ed25519-public"})):
        with pytest.raises(UpdateRefused, match="downgrade authorisation refused"):
            policy.check_newer(old, n, new, o, auth=signed, downgrade=junk)
