"""edge.calibration.model: a calibration's values, covariance and file, and every way a file can be wrong."""

from __future__ import annotations

import json

import numpy as np
import pytest

from edge.calibration.model import CalibrationError, ProbeCalibration, ReferenceFit
from edge.estimation.sensor_chain import SensorChainCalibration
from edge.physics.probe import FLUX_SENSITIVITY_U_REL


def _cal() -> ProbeCalibration:
    return ProbeCalibration(probe="paper", chain=SensorChainCalibration(sensing_thickness_m=4.2e-4, tc_tau_s=0.05,
                                                                         flux_scale=0.97),
                            covariance=np.diag([1e-4, 4e-4, 1e-5, 2e-4]), u_rel_floor=0.012, calibrated=True,
                            created_utc="2026-11-23T00:00:00Z",
                            references=(ReferenceFit("pmma", 558.0, 0.03, 2, (0.01, -0.004)),))


def test_round_trip_keeps_everything_and_the_identity():
    c = _cal()
    c2 = ProbeCalibration.from_json(c.to_json())
    assert c2 == c and c2.sha256 == c.sha256 and np.array_equal(c2.covariance, c.covariance)
    assert c2 != ProbeCalibration.nominal()
    assert c2.chain == c.chain and c2.references == c.references and c2.calibrated
    assert np.allclose(c2.theta, [np.log(0.97), np.log(4.2e-4), 0.05, np.log(0.214)])


def test_nominal_is_uncalibrated_with_the_datasheet_spreads():
    n = ProbeCalibration.nominal()
    assert not n.calibrated and n.chain == SensorChainCalibration()
    assert n.u_theta[0] == pytest.approx(FLUX_SENSITIVITY_U_REL)


def test_chain_at_moves_only_theta_and_never_lets_the_bead_lead():
    c = _cal()
    ch = c.chain_at([0.0, np.log(5e-4), -0.01, np.log(0.25)])
    assert ch.flux_scale == 1.0 and ch.sensing_thickness_m == pytest.approx(5e-4) and ch.tc_tau_s == 0.0
    # The conductivity moves; the layer's rho c stays.
    assert ch.k_W_mK == pytest.approx(0.25)
    assert ch.k_W_mK / ch.alpha_m2_s == pytest.approx(c.chain.k_W_mK / c.chain.alpha_m2_s)


def _mutate(d, path, value):
    x = d
    for k in path[:-1]:
        x = x[k]
    if value is KeyError:
        del x[path[-1]]
    else:
        x[path[-1]] = value
    return d


@pytest.mark.parametrize("path,value,needle", [
    (("format",), "other", "format"),
    (("schema_version",), 2, "schema_version"),
    (("probe",), "nope", "probe"),
    (("calibrated",), "yes", "calibrated"),
    (("chain", "flux_scale"), 0.0, "chain.flux_scale"),
    (("chain", "sensing_thickness_m"), float("nan"), "chain.sensing_thickness_m"),
    (("chain", "extra"), 1.0, "chain.extra"),
    (("covariance",), [[1, 0], [0, 1]], "covariance"),
    (("covariance",), [[1, 2, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], "covariance"),
    (("covariance",), [[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], "covariance"),
    (("u_rel_floor",), 2.0, "u_rel_floor"),
    (("parameters",), ["a", "b", "c", "d"], "parameters"),
    (("references", 0, "n_touches"), 0, "references[0].n_touches"),
    (("references", 0, "rel_errors"), [None], "references[0].rel_errors"),
    (("chain",), KeyError, "chain"),
])
def test_every_bad_field_is_named(path, value, needle):
    d = json.loads(_cal().to_json())
    d.pop("sha256")
    text = json.dumps(_mutate(d, list(path), value))
    with pytest.raises(CalibrationError, match=needle.replace("[", r"\[").replace("]", r"\]")):
        ProbeCalibration.from_json(text)


def test_a_changed_file_is_caught_by_its_checksum():
    d = json.loads(_cal().to_json())
    d["u_rel_floor"] = 0.0
    with pytest.raises(CalibrationError, match="sha256"):
        ProbeCalibration.from_json(json.dumps(d))


@pytest.mark.parametrize("data,needle", [(b"\xff\xfe", "UTF-8"), (b"{", "not JSON"), (b"[]", "table"),
                                         (b" " * 70000, "too large")])
def test_garbage_is_refused_in_one_line(data, needle):
    with pytest.raises(CalibrationError, match=needle) as exc:
        ProbeCalibration.from_json(data)
    assert "\n" not in str(exc.value)


def _checked(misses) -> ProbeCalibration:
    sc = {"method": "leave-one-reference-out", "misses": [
        {"name": n, "e_ref_W_s05_m2K": e, "e_W_s05_m2K": None if rel is None else e * (1 + rel), "u_rel": 0.03,
         "rel_miss": rel, "z": None} for n, e, rel in misses]}
    import dataclasses

    return dataclasses.replace(_cal(), self_check=sc)


def test_the_model_form_term_is_the_floor_within_the_references_and_grows_outside_them():
    """Outside the references' span of e the term grows at the rate the leave-one-out check measured:
    the end reference's rms miss over the ln-e distance its held-out calibration extrapolated."""
    import math

    from edge.calibration.model import extrapolation_rates

    cal = _checked([("pmma", 558.0, 0.04), ("pmma", 558.0, -0.02), ("pyroceram", 2892.0, 0.01),
                    ("aisi_304", 7493.0, -0.05)])
    (e_lo, r_lo), (e_hi, r_hi) = extrapolation_rates(cal)
    rms_lo = math.sqrt((math.log(1.04) ** 2 + math.log(0.98) ** 2) / 2)
    assert (e_lo, e_hi) == (558.0, 7493.0)
    assert r_lo == pytest.approx(rms_lo / math.log(2892.0 / 558.0))
    assert r_hi == pytest.approx(-math.log(0.95) / math.log(7493.0 / 2892.0))
    # Within the span: the floor alone.
    for e in (558.0, 1500.0, 7493.0):
        assert cal.model_form_u_rel(e) == pytest.approx(cal.u_rel_floor)
    # A cork (e 92) and copper (e 36 000): the floor and the extrapolation in quadrature, growing with distance.
    assert cal.model_form_u_rel(92.0) == pytest.approx(math.hypot(0.012, r_lo * math.log(558.0 / 92.0)))
    assert cal.model_form_u_rel(36000.0) == pytest.approx(math.hypot(0.012, r_hi * math.log(36000.0 / 7493.0)))
    assert cal.model_form_u_rel(40.0) > cal.model_form_u_rel(92.0) > cal.model_form_u_rel(300.0) > 0.012
    # It survives the file: the term is read from the stored self-check.
    assert ProbeCalibration.from_json(cal.to_json()).model_form_u_rel(92.0) == cal.model_form_u_rel(92.0)


def test_without_a_self_check_the_term_is_the_floor_and_an_unanswered_end_reference_widens_it():
    from edge.calibration.model import UNANSWERED_MISS, extrapolation_rates

    assert _cal().model_form_u_rel(50.0) == 0.012 and extrapolation_rates(_cal()) is None
    lost = _checked([("pmma", 558.0, None), ("pyroceram", 2892.0, 0.0), ("aisi_304", 7493.0, 0.0)])
    (_, r_lo), (_, r_hi) = extrapolation_rates(lost)
    import math

    assert r_lo == pytest.approx(UNANSWERED_MISS / math.log(2892.0 / 558.0)) and r_hi == 0.0
    assert lost.model_form_u_rel(92.0) > 0.3      # a calibration that could not reach pmma says so on a cork
