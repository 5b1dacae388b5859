"""The probe's calibration over the simulated link: CALIBRATION_SET/GET, INFO, and what measurements record.

A probe without a calibration flags every measurement ``uncalibrated`` and still reports the sensor
chain's estimate; once a calibration is installed (verified, signed per the update policy) the flag goes
and each record names the calibration it used.  Refusals are one line and keep what was installed.
"""

from __future__ import annotations


import pytest

from edge.protocol.commands import Command
from edge.protocol.errors import ErrorCode
from host.calibration import install_calibration, read_calibration
from host.client import DeviceError
from host.keys import new_key
from tests.support.calibrations import sample_calibration
from tests.support.daemons import linked_daemon

pytestmark = pytest.mark.hil


def probe(tmp_path, **security):
    return linked_daemon(tmp_path, security=security) if security else linked_daemon(tmp_path)


def test_install_show_and_every_measurement_names_its_calibration(tmp_path):
    with probe(tmp_path) as c:
        assert c.info()["calibrated"] is False
        assert read_calibration(c)[0] is None
        rec = c.measure(contact_time_s=1.0)
        assert "uncalibrated" in rec["flags"]
        assert rec["result"]["sensor_chain"]["calibration_sha256"] is None
        cal = sample_calibration()
        rep = install_calibration(c, cal)
        assert rep["sha256"] == cal.sha256 and rep["probe"] == "paper"
        info = c.info()
        assert info["calibrated"] is True and info["calibration_sha256"] == cal.sha256
        got, raw = read_calibration(c)
        assert got == cal and raw["signed_by"] is None
        rec = c.measure(contact_time_s=1.0)
        assert "uncalibrated" not in rec["flags"]
        assert rec["result"]["sensor_chain"]["calibration_sha256"] == cal.sha256
        # The chain's own answer (or its error) is there; the measurement is never lost over it.
        chain = rec["result"]["sensor_chain"]
        assert "effusivity_W_s05_m2K" in chain or "error" in chain


@pytest.mark.parametrize("text,needle", [
    (sample_calibration(probe="small-heater").to_json_compact(), "small-heater"),
    ('{"format": "x"}', "format"),
    ("not json", "not JSON"),
])
def test_bad_calibrations_are_refused_in_one_line_and_the_installed_one_stays(tmp_path, text, needle):
    with probe(tmp_path) as c:
        good = sample_calibration()
        install_calibration(c, good)
        with pytest.raises(DeviceError) as ei:
            c.request(Command.CALIBRATION_SET, {"calibration": text})
        assert ei.value.code == ErrorCode.MODEL_REJECTED and needle in str(ei.value)
        assert "\n" not in str(ei.value)
        assert c.info()["calibration_sha256"] == good.sha256


def test_a_strict_probe_takes_only_signed_calibrations(tmp_path):
    keys = tmp_path / "trusted_keys"
    key = new_key(keys, "lab")
    (keys / "lab.secret.json").unlink()
    with probe(tmp_path, allow_unsigned=False, trusted_keys_dir=str(keys)) as c:
        cal = sample_calibration()
        with pytest.raises(DeviceError, match="unsigned"):
            install_calibration(c, cal)
        assert c.info()["calibrated"] is False
        install_calibration(c, cal, key=key)
        assert read_calibration(c)[1]["signed_by"] == key.key_id
