"""A calibration to install in tests (fitted values are not needed: any checked, calibrated file is)."""

from __future__ import annotations

import numpy as np

from edge.calibration.model import ProbeCalibration, ReferenceFit
from edge.estimation.sensor_chain import SensorChainCalibration


#: The device identity the tests' strict stores and calibrations share.
DEVICE_ID = "tt-00112233445566ff"


def sample_calibration(probe: str = "paper", flux_scale: float = 0.97, *, created_utc: str = "2026-11-23T00:00:00Z",
                       device_id: str | None = None) -> ProbeCalibration:
    return ProbeCalibration(probe=probe, chain=SensorChainCalibration(sensing_thickness_m=4.1e-4, tc_tau_s=0.03,
                                                                       flux_scale=flux_scale),
                            covariance=np.diag([1.4e-4, 6e-4, 1e-4, 1.6e-3]), u_rel_floor=0.01, calibrated=True,
                            created_utc=created_utc, device_id=device_id,
                            references=(ReferenceFit("pmma", 558.0, 0.03, 2, (0.004, -0.002)),
                                        ReferenceFit("pyroceram", 2892.0, 0.02, 2, (0.001, 0.003))))
