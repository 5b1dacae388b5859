"""The device identity: made once, kept, never overwritten when it is not one (ISSUE #35 §2, #36)."""

import pytest

from edge.storage.identity import DEVICE_ID_RE, IdentityError, load_or_create_device_id


def test_made_at_first_start_and_kept(tmp_path):
    p = tmp_path / "state" / "device_id"
    first = load_or_create_device_id(p)
    assert DEVICE_ID_RE.match(first) and p.read_text() == first + "\n"
    assert load_or_create_device_id(p) == first
    assert load_or_create_device_id(tmp_path / "other") != first  # another device, another name


def test_a_damaged_identity_is_named_not_replaced(tmp_path):
    p = tmp_path / "device_id"
    p.write_text("tt-zz\n")
    with pytest.raises(IdentityError, match="does not hold a device identity"):
        load_or_create_device_id(p)
    assert p.read_text() == "tt-zz\n"
