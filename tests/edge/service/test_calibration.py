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
        if "error" not in chain and chain["effusivity_W_s05_m2K"] is not None:
            # Which quantities the touch determined, and the object's alpha and k (measured when listed).
            assert "e" in chain["determined"] and chain["alpha_m2_s"] > 0 and chain["k_W_mK"] > 0
        # Calibrated and trusted, the chain's e is the answer and the default method's is kept beside it;
        # otherwise the default method's stays first.
        from edge.estimation.seam import BLOCKERS
        res = rec["result"]
        assert res["calibration_sha256"] == cal.sha256   # the answer names the calibration it used
        if "error" in chain or BLOCKERS & set(chain.get("flags") or ()):
            assert res["method"] == "default" and "default_method" not in res
        else:
            assert res["method"] == "sensor_chain" and res["default_method"]["method"] == "default"
            assert res["effusivity_W_s05_m2K"] == pytest.approx(chain["effusivity_W_s05_m2K"], rel=1e-4)
            assert res["object"] is not None


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


# -- the calibrated chain's answer comes first ------------------------------------------------------
@pytest.fixture(scope="module")
def shipped_estimator():
    from edge.estimation.estimate import Estimator, pipeline_golden_check
    from edge.model.bundle import load_bundle
    from thermotouch_models import DEFAULT_BUNDLE
    return Estimator.from_bundle(load_bundle(DEFAULT_BUNDLE, golden_check=pipeline_golden_check))


def _answer(est, chain_e=620.0, **chain):
    """The default method's answer on e = 560 and a calibrated chain's estimate of e = 620 (with ``chain``)."""
    from edge.estimation.result import Estimate
    from edge.estimation.seam import method_estimate

    base = est.from_effusivity(560.0, 0.02).to_dict()
    base.update(determined=["e"], from_prior=["k", "alpha"], flags=[])
    answer = method_estimate(base, "paper", est.sha256, False)
    assert isinstance(answer, Estimate)
    c = {"effusivity_W_s05_m2K": chain_e, "effusivity_W_s05_m2K_u": 0.015 * chain_e,
         "calibration_sha256": "ab" * 32, "flags": [], **chain}
    return answer, c


def test_a_calibrated_chain_becomes_the_answer_and_the_default_method_is_kept(shipped_estimator):
    from edge.estimation.seam import chain_answer
    est = shipped_estimator
    a, chain = _answer(est)
    before = a.to_dict()
    r = chain_answer(a, chain, est).to_dict()
    assert a.to_dict() == before   # the answer it was made from is not changed (a new one is made)
    assert r["method"] == "sensor_chain" and r["determined_by"] == {"e": "calibration", "k": "prior", "alpha": "prior"}
    assert r["effusivity_W_s05_m2K"] == 620.0 and r["effusivity_W_s05_m2K_u"] == pytest.approx(0.015 * 620.0)
    # k, alpha and the material follow from the chain's e exactly as the default method's from its own.
    ref = est.from_effusivity(620.0, 0.015).to_dict()
    for k in ("k_W_mK", "k_W_mK_u", "alpha_m2_s", "alpha_m2_s_u", "material"):
        assert r[k] == pytest.approx(ref[k], rel=1e-12) if isinstance(ref[k], float) else r[k] == ref[k]
    assert r["default_method"]["effusivity_W_s05_m2K"] == before["effusivity_W_s05_m2K"] == pytest.approx(560.0)
    assert r["default_method"]["method"] == "default" and r["default_method"]["material"] == before["material"]
    assert "candidates" not in r["default_method"]   # kept small: a record must fit one reply
    assert chain_answer(chain_answer(a, chain, est), chain, est) is None   # once only: it is the chain's already


@pytest.mark.parametrize("change", [
    {"calibration_sha256": None},              # the datasheet chain: biased too, the default stays first
    {"flags": ["poor_fit"]}, {"flags": ["contact_lost"]}, {"error": "ValueError: x"},
    {"effusivity_W_s05_m2K": None}, {"effusivity_W_s05_m2K_u": float("nan")},
])
def test_the_default_method_stays_first_when_the_chain_cannot_be_trusted(shipped_estimator, change):
    from edge.estimation.seam import chain_answer
    a, chain = _answer(shipped_estimator, **change)
    assert chain_answer(a, chain, shipped_estimator) is None


def test_no_chain_answer_without_a_model_or_for_the_small_heater(shipped_estimator):
    from dataclasses import replace

    from edge.estimation.seam import chain_answer
    a, chain = _answer(shipped_estimator)
    assert chain_answer(a, chain, None) is None                      # no model: no prior for k and alpha
    assert chain_answer(replace(a, method="axisym"), chain, shipped_estimator) is None


@pytest.mark.parametrize("decision, flagged", [
    ({"stopped_early": True, "object": "window"}, True),       # the answer names another object
    ({"stopped_early": True, "object": None}, False),          # the running answer named none
    ({"stopped_early": False, "object": "window"}, False),     # ran its full time
    (None, False),                                             # no running decision
])
def test_an_early_stop_the_result_does_not_confirm_is_flagged(shipped_estimator, decision, flagged):
    from edge.estimation.record import TouchRecord
    from edge.estimation.seam import SeamContext, estimate_touch
    from edge.recognition import ObjectSet
    from edge.service.config import Config
    from edge.status import Flag
    from firmware_sim.rigs.contact_record import ContactTouch, record_touch
    from edge.physics.materials import load_materials

    glass = load_materials().get("tempered_glass")
    touch = ContactTouch(solid=glass.solid)
    r = record_touch(touch, seed=1)
    rec = TouchRecord(probe="paper", t_s=r["t_s"], T_C=r["T_C"], q_W_m2=r["q_W_m2"], power_W=5.0,
                      heater_on_s=touch.heat_s, sample_rate_Hz=1.0 / float(r["t_s"][1] - r["t_s"][0]),
                      baseline_s=0.5, arm_s=touch.pre_s + touch.lead_s)
    ctx = SeamContext(estimator=shipped_estimator, object_set=ObjectSet.from_library(),
                      thresholds=Config().measurement)
    est = estimate_touch(rec, ctx, decision=decision)
    assert est.object not in (None, "unknown", "window")
    assert (Flag.DECISION_DISAGREES in est.flags) is flagged
    assert (Flag.DECIDED in est.flags) is bool(decision and decision["stopped_early"])
    assert est.to_dict().get("decision") == decision   # kept as the device had it, beside the answer
