"""Shared fixtures of the storage tests."""

import json

import pytest

from edge.security.keys import SecretKey
from edge.security.policy import UpdatePolicy


@pytest.fixture
def keys(tmp_path):
    """Two signing keys and a policy that trusts both: ``(k1, k2, policy)``."""
    k1, k2 = SecretKey.generate(), SecretKey.generate()
    d = tmp_path / "trusted"
    d.mkdir()
    for k in (k1, k2):
        (d / f"{k.key_id}.json").write_text(json.dumps(k.public_key().document()))
    return k1, k2, UpdatePolicy(str(d))
