"""signature.json travels with a bundle: in its directory, in the transport blob, into the store."""

from __future__ import annotations

import hashlib

import pytest

from edge.estimation.estimate import mlp_golden_check
from edge.model import bundle as B
from edge.model.store import InstallError, ModelStore
from edge.security.keys import SecretKey, signature_document
from tests.support.bundles import make_arrays, make_golden, manifest_extra


@pytest.fixture(scope="module")
def bundle(tmp_path_factory):
    arrays = make_arrays(seed=7, hidden=(6, 3))
    return B.write_bundle(tmp_path_factory.mktemp("b") / "b", arrays, make_golden(arrays), manifest_extra("s"),
                          golden_check=mlp_golden_check)


def test_blob_carries_the_signature_and_unpacks_it(tmp_path, bundle):
    sig = signature_document(SecretKey.generate(), (bundle.path / B.MANIFEST_FILE).read_bytes())
    blob = B.bundle_to_bytes(bundle.path, signature=sig)
    assert B.parse_blob(blob)[B.SIGNATURE_FILE] == sig
    out = B.bundle_from_bytes(blob, tmp_path / "u")
    assert B.read_signature(out) == sig
    assert B.load_bundle(out, mlp_golden_check).sha256 == bundle.sha256  # not part of the identity
    # The directory's own signature.json is sent by default.
    assert B.parse_blob(B.bundle_to_bytes(out))[B.SIGNATURE_FILE] == sig
    assert B.SIGNATURE_FILE not in B.parse_blob(B.bundle_to_bytes(bundle.path))


def test_blob_entries_are_still_bounded(bundle):
    files = {n: (bundle.path / n).read_bytes() for n in B.BUNDLE_FILES}
    entries = [(n.encode(), files[n]) for n in B.BUNDLE_FILES]
    with pytest.raises(B.SizeLimitError, match="signature.json"):
        B.parse_blob(B.pack_entries(entries + [(b"signature.json", b" " * (B.MAX_SIGNATURE_BYTES + 1))]))
    with pytest.raises(B.UnsafePathError, match="not one of"):
        B.parse_blob(B.pack_entries(entries + [(b"extra.json", b"{}")]))
    with pytest.raises(B.TransportError, match=r"lacks \['golden.npz'\]"):
        B.parse_blob(B.pack_entries(entries[:2] + [(b"signature.json", b"{}")]))
    with pytest.raises(B.TransportError, match="holds 5 entries"):
        B.parse_blob(B.pack_entries(entries + [(b"signature.json", b"{}")] * 2))


def test_a_store_without_a_policy_refuses_every_upload(tmp_path, bundle):
    store = ModelStore(tmp_path / "s", bundle.path, golden_check=mlp_golden_check)
    blob = B.bundle_to_bytes(bundle.path)
    with pytest.raises(InstallError, match="no update policy"):
        store.install(blob, hashlib.sha256(blob).hexdigest(), len(blob))
    assert store.current().sha256 == bundle.sha256 and store.source == "factory"
