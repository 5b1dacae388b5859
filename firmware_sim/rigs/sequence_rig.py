"""One touch through the device's own measurement code on a scene's simulator, without a daemon.

The device's :class:`~edge.measure.sequence.MeasurementSequence` with its drivers on the scene's
emulated board, and the daemon's estimate path (:func:`edge.estimation.seam.estimate_touch` on
:class:`~edge.service.estimator.ModelEstimator`'s context: the configured probe head's estimator, no
calibration, no object set) on a given bundle: what a MEASURE does, minus the serial link and the history. Used by the small-heater tests and bench, which need many touches on scenes
built in code.
"""

from __future__ import annotations

from typing import Any, Mapping

from edge.hw.chips import sample_rate_Hz
from edge.hw.drivers.heater import Heater
from edge.measure.sensors import make_sensors, thermocouple_resolution_K
from edge.measure.sequence import MeasurementParams, MeasurementSequence
from edge.measure.watchdog import Limits
from edge.estimation.seam import TouchEstimator
from edge.service.config import Config
from edge.service.estimator import ModelEstimator
from firmware_sim.run import config_for_scene
from firmware_sim.simulator import Simulator

__all__ = ["OneBundleStore", "sequence_touch", "sequence_run"]


class OneBundleStore:
    """The one method of :class:`edge.model.store.ModelStore` the estimator uses, on a fixed bundle."""

    def __init__(self, bundle: Any) -> None:
        self.bundle = bundle

    def current(self) -> Any:
        return self.bundle


def sequence_touch(scene: Any, store: Any, workdir: str, overrides: Mapping[str, Mapping[str, Any]] | None = None
                   ) -> tuple[Any, Config, dict]:
    """One touch of ``scene`` through the device's sequence and estimator.

    Parameters
    ----------
    scene : firmware_sim Scene
    store : object with ``current()`` -> bundle (:class:`OneBundleStore`, or a ModelStore)
    workdir : str
        Directory for the configuration's paths (nothing is written there by a touch).
    overrides : mapping, optional
        Extra configuration ``{section: {key: value}}`` (e.g. the contact time).

    Returns
    -------
    outcome : edge.measure.sequence outcome (``status``, ``reason``, ``flags``, ``result``)
    config : Config
        The device configuration the touch ran with.
    invariant : dict
        The heater invariant read from the simulated hardware (``ok``, ``longest_on_s`` ...).
    """
    return sequence_run(scene, store, workdir, overrides)


def sequence_run(scene: Any, store: Any, workdir: str, overrides: Mapping[str, Mapping[str, Any]] | None = None,
                 **params: Any) -> tuple[Any, Config, dict]:
    """:func:`sequence_touch` with MEASURE's own arguments (``arm_s``, ``settle_s``, ``contact_time_s`` ...).

    ``params`` override the :class:`~edge.measure.sequence.MeasurementParams` the configuration gives
    (power, contact time, baseline and sample rate from the scene's configuration; no cool-down).
    """
    sim = Simulator(scene)
    try:
        cfg = config_for_scene(scene, workdir, overrides)
        h, m = cfg.heater, cfg.measurement
        board = sim.board()
        heater = Heater(board, supply_voltage_V=h.supply_voltage_V, resistance_ohm=h.resistance_ohm)
        est = ModelEstimator(store, thermocouple_resolution_K(cfg.sensors), probe=cfg.board.probe)
        seq = MeasurementSequence(heater, make_sensors(board, cfg.sensors), board.clock,
                                  Limits(h.max_on_time_s, h.over_temperature_C, h.fault_flux_W_m2, h.fault_rise_K),
                                  TouchEstimator(est.context(thresholds=m)), m, probe=cfg.board.probe)
        try:
            out = seq.run(MeasurementParams(**{"power_W": h.power_W, "contact_time_s": m.contact_time_s,
                                               "baseline_s": m.baseline_s,
                                               "sample_rate_Hz": sample_rate_Hz(cfg.sensors, m.sample_rate_Hz),
                                               "cooldown_s": 0.0, **params}))
        finally:
            seq.close()
        return out, cfg, sim.heater_invariant(h.max_on_time_s)
    finally:
        sim.close()
