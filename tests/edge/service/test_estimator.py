"""ModelEstimator (edge.service.estimator): the probe head in the configuration decides the estimator."""

from __future__ import annotations

import numpy as np
import pytest

from edge.estimation.estimate import Estimator, pipeline_golden_check
from edge.model.bundle import load_bundle
from edge.physics.axisym import AxisymModel
from edge.physics.forward import simulate
from edge.physics.geometry import PROBES
from edge.physics.probe import HEATER_VOLUME_m3
from edge.physics.solids import Solid
from edge.service.config import Config, ConfigError
from edge.service.estimator import ModelEstimator
from firmware_sim.rigs.sequence_rig import OneBundleStore

GLASS = Solid(1.097, 2458.4, 809.0)


@pytest.fixture(scope="module")
def store():
    from thermotouch_models import DEFAULT_BUNDLE

    return OneBundleStore(load_bundle(DEFAULT_BUNDLE, golden_check=pipeline_golden_check))


def test_config_probe_defaults_to_paper_and_takes_only_shipped_probes():
    assert Config().board.probe == "paper"
    assert Config({"board": {"probe": "small-heater"}}).board.probe == "small-heater"
    with pytest.raises(ConfigError, match="board.probe"):
        Config({"board": {"probe": "tiny"}})
    with pytest.raises(ConfigError, match="run time"):  # hardware: set in the file, not over the link
        Config().with_updates({"board.probe": "small-heater"})


def test_paper_probe_takes_the_unchanged_1d_path(store):
    r = simulate(GLASS, 7.7e7, 2.0, back="infinite", scheme="exact", dt_s=0.1)
    power_W = 7.7e7 * HEATER_VOLUME_m3   # the estimators take the power in W (issue #33: no q_v round trip)
    got = ModelEstimator(store, 0.0)(r.t_s, r.T_f_K, r.q_f_W_m2, power_W, "default")
    want = Estimator.from_bundle(store.bundle).estimate(r.t_s, r.T_f_K, r.q_f_W_m2, q_v_W_m3=7.7e7).to_dict()
    # Same keys and values (to rounding: two runs of the same path may differ in the last bit), plus what
    # every probe head's estimator says (edge.estimation.methods): the probe and what the touch determined.
    assert set(got) - set(want) == {"probe", "determined", "from_prior", "series"}   # series: the fit's arrays
    assert got["determined"] == ["e"] and got["from_prior"] == ["k", "alpha"] and got["probe"] == "paper"
    for key, v in want.items():
        assert got[key] == _approx(v), key


def _approx(v):
    """``v`` with every float in it, however nested (the candidates are [name, score] pairs), to 1e-12."""
    if isinstance(v, float):
        return pytest.approx(v, rel=1e-12)
    if isinstance(v, (list, tuple)):
        return type(v)(_approx(x) for x in v)
    if isinstance(v, dict):
        return {k: _approx(x) for k, x in v.items()}
    return v


def test_small_heater_probe_takes_the_axisymmetric_fit(store):
    g = PROBES["small-heater"]
    t = np.arange(101) * 0.05
    T, q = AxisymModel(g, t).signals(GLASS.k_W_mK, GLASS.alpha_m2_s)
    me = ModelEstimator(store, 0.0, probe="small-heater")
    d = me(t, T, q, g.nominal_power_W, "default")
    assert d["method"] == "axisym" and d["probe"] == "small-heater"
    assert d["determined"] == ["e", "k", "alpha"]
    assert d["k_W_mK"] == pytest.approx(GLASS.k_W_mK, rel=0.02)
    assert d["fit"]["power_scale"] == pytest.approx(1.0, rel=1e-3)  # the power was passed through


def test_unknown_probe_refused(store):
    with pytest.raises(ValueError, match="unknown probe"):
        ModelEstimator(store, probe="tiny")


def test_daemon_builds_its_estimator_for_the_configured_probe(tmp_path):
    from edge.service.daemon import Daemon
    from firmware_sim.rigs.daemon_rig import make_rig
    from tests.support.daemons import FakeEstimator, sim_config

    d = Daemon(sim_config(tmp_path, board={"probe": "small-heater"}), make_rig().board, estimator=FakeEstimator())
    try:
        assert d._model_est.probe == "small-heater"
    finally:
        d.close()
