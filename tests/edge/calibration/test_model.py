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
