"""Signed model updates over the simulated daemon and the virtual serial link.

A probe configured like a real one (``security.allow_unsigned = false``)
installs a bundle signed by a key in its ``trusted_keys_dir`` and refuses an
unsigned one, one signed by another key, one whose manifest was changed after
signing, and a signed one that is not newer than its model unless the upload
carries a signed authorisation for exactly that rollback; every refusal is one
line and leaves the old model serving.
"""

from __future__ import annotations


import pytest

from edge.estimation.estimate import mlp_golden_check
from edge.model import bundle as B
from edge.protocol.errors import ErrorCode
from edge.security.keys import SecretKey, downgrade_document, signature_document
from host.client import DeviceError
from host.device import describe_error
from tests.support.bundles import make_arrays, make_golden, manifest_extra
from tests.support.daemons import strict_probe

pytestmark = pytest.mark.hil


def _bundle(d, tag, seed, created_utc):
    arrays = make_arrays(seed=seed, hidden=(12, 5))
    extra = {**manifest_extra(tag), "created_utc": created_utc}
    return B.write_bundle(d / tag, arrays, make_golden(arrays), extra, golden_check=mlp_golden_check)


@pytest.fixture(scope="module")
def bundles(tmp_path_factory):
    d = tmp_path_factory.mktemp("signed")
    return {
        "factory": _bundle(d, "factory", 1, "2024-01-01T00:00:00Z"),
        "v2": _bundle(d, "v2", 2, "2025-01-01T00:00:00Z"),
        "v3": _bundle(d, "v3", 3, "2025-06-01T00:00:00Z"),
        "v2b": _bundle(d, "v2b", 4, "2024-12-01T00:00:00Z"),  # newer than the factory, older than v3
    }


def _manifest(bundle) -> bytes:
    return (bundle.path / B.MANIFEST_FILE).read_bytes()


def _signed_blob(bundle, key) -> bytes:
    return B.bundle_to_bytes(bundle.path, signature=signature_document(key, _manifest(bundle)))


def _strict(tmp_path, bundles):
    """A daemon that accepts only signed updates (release key), on the test's factory bundle."""
    return strict_probe(tmp_path, "release", paths={"factory_model": str(bundles["factory"].path)})


def _refused(client, blob, **kw) -> str:
    with pytest.raises(DeviceError) as ei:
        client.upload_model(blob, **kw)
    assert ei.value.code == ErrorCode.MODEL_REJECTED
    line = describe_error(ei.value)
    assert "\n" not in line and line.startswith("device refused the bundle: install refused, active model unchanged")
    return line


def test_signed_by_a_trusted_key_is_installed(tmp_path, bundles):
    with _strict(tmp_path, bundles) as (c, key):
        assert c.info()["model_sha256"] == bundles["factory"].sha256
        res = c.upload_model(_signed_blob(bundles["v2"], key))
        assert res["bundle_sha256"] == bundles["v2"].sha256
        info = c.info()
        assert info["model_sha256"] == bundles["v2"].sha256 and info["model_source"] == "current"


def test_unsigned_untrusted_and_tampered_are_refused_and_the_old_model_serves(tmp_path, bundles):
    with _strict(tmp_path, bundles) as (c, key):
        line = _refused(c, B.bundle_to_bytes(bundles["v2"].path))
        assert "unsigned update refused" in line

        stranger = SecretKey.generate()
        line = _refused(c, _signed_blob(bundles["v2"], stranger))
        assert f"signature by untrusted key {stranger.key_id} refused" in line

        # Manifest edited after signing (its file hashes still match, so only the signature catches it).
        files = B.parse_blob(_signed_blob(bundles["v2"], key))
        files[B.MANIFEST_FILE] = files[B.MANIFEST_FILE].replace(b'"test bundle"', b'"test bundlf"')
        tampered = B.pack_entries([(n.encode(), files[n]) for n in (*B.BUNDLE_FILES, B.SIGNATURE_FILE)])
        line = _refused(c, tampered)
        assert f"bad signature by key {key.key_id}: signature does not verify" in line

        # A signature.json that is not one.
        files[B.SIGNATURE_FILE] = b'{"key_id": "zz"}'
        line = _refused(c, B.pack_entries([(n.encode(), files[n]) for n in (*B.BUNDLE_FILES, B.SIGNATURE_FILE)]))
        assert "signature refused: signature.json: 'key_id' must be 16 lowercase hex digits" in line

        info = c.info()
        assert info["model_sha256"] == bundles["factory"].sha256 and info["model_source"] == "factory"
        assert c.measure(contact_time_s=0.5)["status"] == "ok"  # still measuring with the old model


def test_older_signed_version_is_refused_unless_a_signed_authorisation_names_it(tmp_path, bundles):
    with _strict(tmp_path, bundles) as (c, key):
        c.upload_model(_signed_blob(bundles["v3"], key))
        line = _refused(c, _signed_blob(bundles["v2b"], key))
        assert ("downgrade refused: update 'v2b' created 2024-12-01T00:00:00Z is not newer than the active 'v3' "
                "created 2025-06-01T00:00:00Z (a rollback needs a signed authorisation: "
                "thermotouch flash --force --key FILE)") in line
        assert c.info()["model_sha256"] == bundles["v3"].sha256
        # Re-sending the model that runs is not a downgrade.
        assert c.upload_model(_signed_blob(bundles["v3"], key))["bundle_sha256"] == bundles["v3"].sha256
        # ISSUE #35 §1: a rollback asked for by anyone on the link (a stranger's authorisation, or one
        # for another pair of models) is refused; the model that runs stays.
        v2b, v3 = bundles["v2b"].sha256, bundles["v3"].sha256
        line = _refused(c, _signed_blob(bundles["v2b"], key),
                        downgrade=downgrade_document(SecretKey.generate(), v2b, v3))
        assert "downgrade authorisation by untrusted key" in line
        _refused(c, _signed_blob(bundles["v2b"], key), downgrade=downgrade_document(key, v2b, bundles["v2"].sha256))
        assert c.info()["model_sha256"] == v3
        # The operator's deliberate rollback: signed, for exactly this bundle over exactly this model.
        auth = downgrade_document(key, v2b, v3)
        res = c.upload_model(_signed_blob(bundles["v2b"], key), downgrade=auth)
        assert res["bundle_sha256"] == v2b and c.info()["model_sha256"] == v2b
        # Spent: after v3 runs again, the same authorisation does not roll it back a second time ...
        c.upload_model(_signed_blob(bundles["v3"], key))
        assert c.info()["model_sha256"] == v3
        assert "this downgrade authorisation was used before" in _refused(
            c, _signed_blob(bundles["v2b"], key), downgrade=auth)
        assert c.info()["model_sha256"] == v3
        # ... and an authorisation never skips the bundle's own signature.
        _refused(c, B.bundle_to_bytes(bundles["v2b"].path), downgrade=auth)
