"""What the sensors do to the signals: sampling, noise and ADC quantisation.

Used to make simulated measurements and training-set augmentation match the
simulated hardware (firmware_sim) and the reference board:

* ``"mcp9600"`` - MCP9600 in its 16-bit mode (80-ms conversions, 12.5 Hz):
  its ADC resolves 8 uV of thermocouple EMF, i.e. 0.197 K steps (the
  0.0625 K register LSB only pays off at 18 bit, 320 ms per conversion),
  and the FHF05 flux sensor (0.56 uV per W/m^2) on an ADS1115 at +-0.256 V
  (7.8125 uV LSB = 14 W/m^2) at 128 SPS.
* ``"ads122c04"`` - the precision option: thermocouple EMF and flux on a
  24-bit ADS122C04 at gain 128 (0.12 uV LSB), 90 SPS.

Noise figures are input-referred RMS values typical of the datasheets plus
pick-up on a short cable.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from edge.hw.regmaps.mcp9600 import adc_step_V
from edge.physics.probe import FLUX_SENSITIVITY_V_per_W_m2
from edge.physics.typek import seebeck_uV_per_K

TYPE_K_SEEBECK_V_per_K = float(seebeck_uV_per_K(25.0)) * 1e-6
#: ADS122C04 step at gain 128 with the internal 2.048 V reference (24-bit two's complement).
ADS122C04_STEP_V = 2.048 / 128 / 2 ** 23


@dataclass(frozen=True)
class Instrument:
    """Sampling and noise model of a sensor chain (SI units)."""

    name: str
    T_rate_Hz: float
    T_lsb_K: float
    T_noise_K: float
    q_rate_Hz: float
    q_lsb_W_m2: float
    q_noise_W_m2: float
    q_range_W_m2: float = 10e3

    def sample(self, t_s: np.ndarray, T_K: np.ndarray, q_W_m2: np.ndarray, rng: np.random.Generator,
               t0_offset_K: float = 0.0):
        """Sample a continuous record (given densely on ``t_s``) the way the chips would.

        Returns (tT, T_meas, tq, q_meas): each sensor on its own time grid,
        with noise, quantisation (of the absolute temperature, offset by
        ``t0_offset_K`` so the LSB grid is not aligned with T0) and flux range clipping.
        """
        tT = np.arange(0.0, t_s[-1] + 1e-12, 1.0 / self.T_rate_Hz)
        tq = np.arange(0.0, t_s[-1] + 1e-12, 1.0 / self.q_rate_Hz)
        T = self.read_T(np.interp(tT, t_s, T_K), rng, t0_offset_K)
        q = self.read_q(np.interp(tq, t_s, q_W_m2), rng)
        return tT, T, tq, q

    def read_T(self, T_K: np.ndarray, rng: np.random.Generator, offset_K: float = 0.0) -> np.ndarray:
        """The thermometer's readings of true temperatures: noise, then quantisation of the value
        shifted by ``offset_K`` (so the LSB grid is not aligned with the baseline)."""
        T = np.asarray(T_K, float) + offset_K + rng.normal(0.0, self.T_noise_K, np.size(T_K))
        return np.round(T / self.T_lsb_K) * self.T_lsb_K - offset_K

    def read_q(self, q_W_m2: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """The flux converter's readings of true fluxes: noise, quantisation, range clipping."""
        q = np.asarray(q_W_m2, float) + rng.normal(0.0, self.q_noise_W_m2, np.size(q_W_m2))
        return np.clip(np.round(q / self.q_lsb_W_m2) * self.q_lsb_W_m2, -self.q_range_W_m2, self.q_range_W_m2)


INSTRUMENTS = {
    "mcp9600": Instrument(
        name="mcp9600", T_rate_Hz=12.5, T_lsb_K=adc_step_V(16) / TYPE_K_SEEBECK_V_per_K, T_noise_K=0.02,
        q_rate_Hz=128.0, q_lsb_W_m2=7.8125e-6 / FLUX_SENSITIVITY_V_per_W_m2, q_noise_W_m2=3.0,
    ),
    "ads122c04": Instrument(
        name="ads122c04", T_rate_Hz=90.0, T_lsb_K=ADS122C04_STEP_V / TYPE_K_SEEBECK_V_per_K,
        T_noise_K=0.004, q_rate_Hz=90.0, q_lsb_W_m2=ADS122C04_STEP_V / FLUX_SENSITIVITY_V_per_W_m2,
        q_noise_W_m2=1.0,
    ),
}
