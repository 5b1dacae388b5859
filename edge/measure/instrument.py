"""What the sensors do to the signals: sampling, noise and ADC quantisation.

Used to make simulated measurements and training-set augmentation match the
simulated hardware (firmware_sim) and the boards. One :class:`Instrument` per
board of the chip registry (:data:`edge.hw.chips.BOARDS`), named after its
thermocouple chip and built from the registry's noise models
(:attr:`edge.hw.chips.Chip.models`) of the chip that plays each role. Today
that gives

* ``"mcp9600"`` -- the reference board: MCP9600 in its 16-bit mode (12.5 Hz,
  0.197 K steps) and the flux sensor on an ADS1115 at +-0.256 V (14 W/m^2
  steps) at 128 SPS;
* ``"ads122c04"`` -- the precision board: thermocouple EMF and flux on a
  24-bit ADS122C04 at gain 128 (0.12 uV LSB), 90 SPS.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from edge.hw.chips import ADS122C04_STEP_V, BOARDS, CHIPS, FLUX, THERMOCOUPLE, TYPE_K_SEEBECK_V_per_K, Chip

__all__ = ["Instrument", "INSTRUMENTS", "instrument_for", "TYPE_K_SEEBECK_V_per_K", "ADS122C04_STEP_V"]


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


def instrument_for(thermocouple: Chip, flux: Chip) -> Instrument:
    """The sampling and noise model of a board with these two chips (their registry noise models)."""
    T, q = thermocouple.models[THERMOCOUPLE], flux.models[FLUX]
    return Instrument(name=thermocouple.name, T_rate_Hz=T.rate_Hz, T_lsb_K=T.lsb, T_noise_K=T.noise,
                      q_rate_Hz=q.rate_Hz, q_lsb_W_m2=q.lsb, q_noise_W_m2=q.noise)


#: Instrument models by name (the board's thermocouple chip): one per board of the registry.
INSTRUMENTS = {board[THERMOCOUPLE]: instrument_for(CHIPS[board[THERMOCOUPLE]], CHIPS[board[FLUX]])
               for board in BOARDS.values()}
