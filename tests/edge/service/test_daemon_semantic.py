"""Over the simulated serial link: the daemon refuses a self-consistent but wrong bundle, the old one serves."""

import serial

import pytest

from edge.model import bundle as B
from firmware_sim.daemon_thread import DaemonThread
from firmware_sim.ptylink import NullModem
from firmware_sim.rigs.daemon_rig import make_rig
from edge.protocol.errors import ErrorCode
from host.client import DeviceClient, DeviceError
from tests.support.bundles import broken_copy
from tests.support.daemons import FakeEstimator, sim_config
from thermotouch_models import DEFAULT_BUNDLE

pytestmark = pytest.mark.hil


def test_daemon_refuses_permuted_names_and_negated_network_with_a_one_line_reason(tmp_path):
    bad = [broken_copy(DEFAULT_BUNDLE, tmp_path / how, how) for how in ("permuted_names", "negated_output")]
    rig = make_rig()
    cfg = sim_config(tmp_path, paths={"factory_model": str(DEFAULT_BUNDLE)})
    with NullModem() as nm, serial.Serial(nm.device_port, timeout=0.05) as port:
        with DaemonThread(cfg, rig.board, port, estimator=FakeEstimator(rig.parts)) as dt:
            with DeviceClient(nm.host_port, timeout_s=5.0) as c:
                factory = c.info()["model_sha256"]
                for b in bad:
                    with pytest.raises(DeviceError) as ei:
                        c.upload_model(B.bundle_to_bytes(b.path))
                    assert ei.value.code == ErrorCode.MODEL_REJECTED
                    msg = str(ei.value)
                    assert "semantic self-check" in msg and "\n" not in msg
                    assert c.info()["model_sha256"] == factory
                # The shipped bundle itself installs (it passes its own check).
                res = c.upload_model(B.bundle_to_bytes(DEFAULT_BUNDLE))
                assert res["bundle_sha256"] == factory and c.info()["model_source"] == "current"
        assert dt.error is None
