"""edge.storage.calibration_store: install verified, refuse in one line, never half a file."""

from __future__ import annotations

import pytest

from edge.calibration.model import MAX_BYTES, ProbeCalibration
from edge.security.keys import signature_document
from edge.security.policy import UpdatePolicy
from edge.storage import durable
from edge.storage.calibration_store import CalibrationStore, CalibrationStoreError
from host.keys import new_key
from tests.support.calibrations import sample_calibration

OPEN = UpdatePolicy(allow_unsigned=True)
#: The device's parser and bound (edge.service.calibration gives the store the same).
PARSER = {"parse": ProbeCalibration.from_json, "max_bytes": MAX_BYTES}


def test_empty_store_has_no_calibration_and_install_round_trips(tmp_path):
    st = CalibrationStore(tmp_path / "cal", "paper", OPEN, **PARSER)
    assert st.current() is None
    cal = sample_calibration()
    got = st.install(cal.to_json_compact().encode())
    assert got == cal and st.current() == cal and st.signed_by() is None
    # A second install replaces the first.
    cal2 = sample_calibration(flux_scale=0.95)
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
    st = CalibrationStore(tmp_path / "cal", "paper", strict, **PARSER)
    blob = sample_calibration().to_json_compact().encode()
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
        st.install(sample_calibration(flux_scale=0.9).to_json().encode())
    monkeypatch.undo()
    # A restart sweeps the temporary and reads the old file whole.
    st2 = CalibrationStore(tmp_path / "cal", "paper", OPEN, **PARSER)
    assert st2.current() == old
    assert [p.name for p in (tmp_path / "cal").iterdir()] == ["calibration.json"]
