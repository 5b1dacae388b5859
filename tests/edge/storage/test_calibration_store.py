"""edge.storage.calibration_store: install verified, refuse in one line, never half a file."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from edge.calibration.model import MAX_BYTES, ProbeCalibration
from edge.security.keys import signature_document
from edge.security.policy import UpdatePolicy
from edge.storage import durable
from edge.storage.calibration_store import CalibrationStore, CalibrationStoreError
from host.keys import new_key
from tests.support.calibrations import DEVICE_ID, sample_calibration

OPEN = UpdatePolicy(allow_unsigned=True)
#: The device's parser and bound (edge.service.calibration gives the store the same).
PARSER = {"parse": ProbeCalibration.from_json, "max_bytes": MAX_BYTES}


def test_empty_store_has_no_calibration_and_install_round_trips(tmp_path):
    st = CalibrationStore(tmp_path / "cal", "paper", OPEN, **PARSER)
    assert st.current() is None
    cal = sample_calibration()
    got = st.install(cal.to_json_compact().encode())
    assert got == cal and st.current() == cal and st.signed_by() is None
    # A second, newer install replaces the first.
    cal2 = sample_calibration(flux_scale=0.95, created_utc="2026-11-24T00:00:00Z")
    st.install(cal2.to_json().encode())
    assert st.current() == cal2


@pytest.mark.parametrize("mutate,needle", [
    (lambda c: ProbeCalibration.nominal().to_json(), "uncalibrated"),
    (lambda c: sample_calibration(probe="small-heater").to_json(), "small-heater"),
    (lambda c: c.to_json().replace('"u_rel_floor": 0.01', '"u_rel_floor": 0.02'), "sha256"),
    (lambda c: "{", "not JSON"),
    (lambda c: "x" * 70000, "limit"),
])
def test_bad_calibrations_are_refused_and_the_old_one_stays(tmp_path, mutate, needle):
    st = CalibrationStore(tmp_path / "cal", "paper", OPEN, **PARSER)
    cal = sample_calibration()
    st.install(cal.to_json().encode())
    with pytest.raises(CalibrationStoreError, match=needle) as ei:
        st.install(mutate(cal).encode())
    assert "\n" not in str(ei.value)
    assert st.current() == cal


def test_policy_decides_who_may_install(tmp_path):
    keys = tmp_path / "keys"
    key = new_key(keys, "lab")
    strict = UpdatePolicy(trusted_keys_dir=str(keys), allow_unsigned=False)
    st = CalibrationStore(tmp_path / "cal", "paper", strict, **PARSER, device_id=lambda: DEVICE_ID)
    blob = sample_calibration(device_id=DEVICE_ID).to_json_compact().encode()
    with pytest.raises(CalibrationStoreError, match="unsigned"):
        st.install(blob)
    with pytest.raises(CalibrationStoreError, match="no update policy"):
        CalibrationStore(tmp_path / "c2", "paper", None, **PARSER).install(blob)
    # A signature over other bytes does not verify.
    with pytest.raises(CalibrationStoreError, match="refused"):
        st.install(blob, signature_document(key, blob + b" "))
    assert st.current() is None
    st.install(blob, signature_document(key, blob))
    assert st.signed_by() == key.key_id and st.current() is not None


def test_a_damaged_stored_file_is_named_not_used(tmp_path):
    st = CalibrationStore(tmp_path / "cal", "paper", OPEN, **PARSER)
    st.install(sample_calibration().to_json().encode())
    (tmp_path / "cal" / "calibration.json").write_text('{"format": "thermotouch-calibration"')
    with pytest.raises(CalibrationStoreError, match="damaged"):
        st.current()


def test_a_crash_while_writing_leaves_the_old_calibration(tmp_path, monkeypatch):
    st = CalibrationStore(tmp_path / "cal", "paper", OPEN, **PARSER)
    old = sample_calibration()
    st.install(old.to_json().encode())

    def crash(src, dst):
        raise OSError("power cut")

    monkeypatch.setattr(durable, "replace", crash)
    with pytest.raises(OSError):
        st.install(sample_calibration(flux_scale=0.9, created_utc="2026-11-24T00:00:00Z").to_json().encode())
    monkeypatch.undo()
    # A restart sweeps the temporary and reads the old file whole.
    st2 = CalibrationStore(tmp_path / "cal", "paper", OPEN, **PARSER)
    assert st2.current() == old
    assert [p.name for p in (tmp_path / "cal").iterdir()] == ["calibration.json"]


# -- the file checks itself; the device checks it against itself (ISSUE #34, #35 §2) ----------------
def _strict(tmp_path, keys_dir, **kw):
    return CalibrationStore(tmp_path / "cal", "paper", UpdatePolicy(trusted_keys_dir=str(keys_dir)), **PARSER,
                            device_id=lambda: DEVICE_ID, **kw)


def test_a_file_without_its_sha256_is_refused_on_install_and_on_load(tmp_path):
    import json

    st = CalibrationStore(tmp_path / "cal", "paper", OPEN, **PARSER)
    d = json.loads(sample_calibration().to_json())
    d.pop("sha256")
    blob = json.dumps(d).encode()
    with pytest.raises(CalibrationStoreError, match="sha256: missing"):
        st.install(blob)
    (tmp_path / "cal" / "calibration.json").write_bytes(blob)   # placed by hand
    with pytest.raises(CalibrationStoreError, match="sha256: missing"):
        st.current()


@pytest.mark.parametrize("cal,needle", [
    (lambda: sample_calibration(flux_scale=2.0), "flux_scale: 2 is outside"),
    (lambda: sample_calibration(flux_scale=0.5), "flux_scale: 0.5 is outside"),
    (lambda: replace(sample_calibration(), covariance=np.diag([1e150, 6e-4, 1e-4, 1.6e-3])), "wider than its"),
    (lambda: sample_calibration(created_utc="2099-01-01T00:00:00Z"), "in the future"),
    (lambda: sample_calibration(created_utc="yesterday"), "created_utc"),
    (lambda: sample_calibration(created_utc="2026-11-22T00:00:00Z"), "not newer than the installed"),
])
def test_implausible_future_and_older_calibrations_are_refused_with_the_reason(tmp_path, cal, needle):
    st = CalibrationStore(tmp_path / "cal", "paper", OPEN, **PARSER)
    good = sample_calibration()
    st.install(good.to_json().encode())
    with pytest.raises(CalibrationStoreError, match=needle) as ei:
        st.install(cal().to_json().encode())
    assert "\n" not in str(ei.value) and st.current() == good
    # The same calibration again changes nothing (compact or pretty bytes alike).
    assert st.install(good.to_json_compact().encode()) == good


def test_a_day_of_clock_slack_and_a_newer_calibration_are_accepted(tmp_path):
    from datetime import datetime, timezone

    now = datetime(2026, 11, 23, 0, 0, tzinfo=timezone.utc)
    st = CalibrationStore(tmp_path / "cal", "paper", OPEN, **PARSER, now=lambda: now)
    st.install(sample_calibration(created_utc="2026-11-23T23:00:00Z").to_json().encode())
    with pytest.raises(CalibrationStoreError, match="future"):
        st.install(sample_calibration(created_utc="2026-11-24T01:00:00Z").to_json().encode())


def test_a_calibration_is_bound_to_its_device(tmp_path):
    keys = tmp_path / "keys"
    key = new_key(keys, "lab")

    def signed(cal):
        b = cal.to_json().encode()
        return b, signature_document(key, b)

    st = _strict(tmp_path, keys)
    with pytest.raises(CalibrationStoreError, match="made for device tt-0000000000000001, this device is"):
        st.install(*signed(sample_calibration(device_id="tt-0000000000000001")))
    with pytest.raises(CalibrationStoreError, match="names no device"):
        st.install(*signed(sample_calibration()))
    mine = sample_calibration(device_id=DEVICE_ID)
    assert st.install(*signed(mine)) == mine
    # A device that allows unsigned updates takes an unbound one, never another device's.
    open_st = CalibrationStore(tmp_path / "c2", "paper", OPEN, **PARSER, device_id=lambda: DEVICE_ID)
    open_st.install(sample_calibration(created_utc="2026-11-24T00:00:00Z").to_json().encode())
    with pytest.raises(CalibrationStoreError, match="made for device"):
        open_st.install(sample_calibration(created_utc="2026-11-25T00:00:00Z",
                                           device_id="tt-0000000000000001").to_json().encode())
    # A file copied in from another device is not used.
    other = sample_calibration(created_utc="2026-11-26T00:00:00Z", device_id="tt-0000000000000001")
    (tmp_path / "c2" / "calibration.json").write_text(other.to_json())
    with pytest.raises(CalibrationStoreError, match="made for device tt-0000000000000001"):
        open_st.current()
