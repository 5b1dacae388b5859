"""Signed object-set uploads over the simulated daemon, like signed model updates (test_signed_updates.py).

A probe configured like a real one (``security.allow_unsigned = false``) stores an object set signed by a
key in its ``trusted_keys_dir`` and refuses an unsigned one, one signed by another key and one whose CSV
was changed after signing; every refusal is one line and leaves the active set as it was.
"""

from __future__ import annotations

import hashlib

import pytest

from edge.protocol.commands import Command
from edge.protocol.errors import ErrorCode
from edge.security.keys import SecretKey, signature_document
from host.client import DeviceError
from host.objects import list_object_sets, upload_object_set
from tests.support.daemons import strict_probe

pytestmark = pytest.mark.hil

KITCHEN = b"name,class,e_W_s05_m2K\nmug,ceramic,1400\nsponge,foam,60\n"
DESK = b"name,class,e_W_s05_m2K\ndesk,wood,400\n"


def _refused(client, name, data, key=None) -> str:
    with pytest.raises(DeviceError) as ei:
        upload_object_set(client, name, data, key=key)
    assert ei.value.code == ErrorCode.MODEL_REJECTED
    assert "\n" not in str(ei.value)
    return str(ei.value)


def test_signed_sets_are_stored_and_others_refused_with_the_active_set_kept(tmp_path):
    with strict_probe(tmp_path) as (c, key):
        res = upload_object_set(c, "kitchen", KITCHEN, key=key)
        assert res["active"] == "kitchen" and res["objects"] == 2
        (listed,) = list_object_sets(c)["sets"]
        assert listed["name"] == "kitchen" and listed["signed_by"] == key.key_id

        assert "unsigned update refused" in _refused(c, "desk", DESK)
        stranger = SecretKey.generate()
        assert f"signature by untrusted key {stranger.key_id} refused" in _refused(c, "desk", DESK, stranger)

        # The CSV changed after signing (the sha256 announced is the changed file's): only the signature catches it.
        sig = signature_document(key, DESK).decode()
        tampered = DESK.replace(b"400", b"410")
        begin = c.request(Command.OBJECTS_BEGIN, {"name": "desk", "size": len(tampered),
                                                  "sha256": hashlib.sha256(tampered).hexdigest(), "signature": sig})
        c.request(Command.OBJECTS_CHUNK, {"offset": 0, "data": tampered, "session": begin["session"]})
        with pytest.raises(DeviceError) as ei:
            c.request(Command.OBJECTS_COMMIT, {"session": begin["session"]})
        assert ei.value.code == ErrorCode.MODEL_REJECTED and f"bad signature by key {key.key_id}" in str(ei.value)

        after = list_object_sets(c)
        assert after["active"] == "kitchen" and [s["name"] for s in after["sets"]] == ["kitchen"]
