"""The probe's two sensors -- thermocouple and heat-flux sensor -- as one reading source.

:func:`make_sensors` builds :class:`ProbeSensors` from the ``[sensors]``
configuration section: it probes and configures the converter chips through
the board's I2C bus and wraps them in two read functions.
:func:`thermocouple_resolution_K` gives the temperature step of the same
configured converter, which the estimator carries into its uncertainty.

Nothing here imports the simulator; the chips are reached through the board.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

from edge.hw.drivers.ads1115 import ADS1115
from edge.hw.drivers.ads122c04 import ADS122C04
from edge.hw.drivers.mcp9600 import MCP9600
from edge.hw.regmaps.mcp9600 import adc_step_V
from edge.hw.faults import SensorFault
from edge.measure.instrument import ADS122C04_STEP_V, TYPE_K_SEEBECK_V_per_K

__all__ = ["Reading", "ProbeSensors", "make_sensors", "thermocouple_resolution_K"]


@dataclass(frozen=True)
class Reading:
    """One sample: thermocouple (°C), heat flux (W/m^2), whether an ADC clipped, and when each was read.

    ``T_dt_s`` and ``q_dt_s`` place each sensor's reading relative to the
    midpoint of the whole read (s; 0 when the sensors are not timed): the two
    are converted one after the other (the ADS122C04 in two single shots,
    ~1.5 ms apart at 1000 SPS), and on the small-heater probe a skew of that
    size between the thermocouple and the flux record is a time-shape error
    the axisymmetric fit turns into k and alpha: -5 % / -7 % on glass at
    50 Hz when both are stamped at the midpoint, +5 % / +9 % with the reads
    swapped (bench/small_probe_bench.py).
    """

    T_C: float
    q_W_m2: float
    saturated: bool = False
    T_dt_s: float = 0.0
    q_dt_s: float = 0.0


class ProbeSensors:
    """Reads the thermocouple and the flux sensor through the chip drivers.

    Parameters
    ----------
    read_T : callable () -> (float °C, bool saturated)
    read_q_V : callable () -> (float V, bool saturated)
    flux_sensitivity_V_per_W_m2 : float
    description : str
        Which chips are read (for logs).
    T_age_s : float
        Mean age (s) of a temperature reading when it is read.
    T_resolution_K : float
        The thermometer's step (K), 0 if unknown.
    clock : callable () -> float, optional
        Monotonic time (s; the board clock): each sensor's read is then timed
        (:attr:`Reading.T_dt_s`, :attr:`Reading.q_dt_s`).
    T_lag_s, q_lag_s : float
        Time from the instant a single-shot reading samples its input to the
        end of its read (s): half the last conversion (the ADC integrates over
        it). 0 for a continuously converting chip (its age is ``T_age_s``).
    """

    def __init__(self, read_T: Callable[[], tuple[float, bool]], read_q_V: Callable[[], tuple[float, bool]],
                 flux_sensitivity_V_per_W_m2: float, *, description: str = "", T_age_s: float = 0.0,
                 T_resolution_K: float = 0.0, clock: Callable[[], float] | None = None, T_lag_s: float = 0.0,
                 q_lag_s: float = 0.0) -> None:
        if not flux_sensitivity_V_per_W_m2 > 0:
            raise ValueError(f"flux_sensitivity_V_per_W_m2 must be > 0, got {flux_sensitivity_V_per_W_m2!r}")
        if not T_age_s >= 0:
            raise ValueError(f"T_age_s must be >= 0, got {T_age_s!r}")
        #: Mean age (s) of a temperature reading when it is read: a converter that
        #: converts continuously holds a value taken one conversion time ago on average.
        self.T_age_s = float(T_age_s)
        #: The thermometer's step (K), 0 if unknown.
        self.T_resolution_K = float(T_resolution_K)
        self._read_T = read_T
        self._read_q_V = read_q_V
        self.sensitivity = float(flux_sensitivity_V_per_W_m2)
        self.description = description
        self._clock = clock
        self._T_lag_s = float(T_lag_s)
        self._q_lag_s = float(q_lag_s)

    def read(self) -> Reading:
        """One reading of both sensors (SensorFault on failure), each timed when a clock is given."""
        if self._clock is None:
            T, sat_T = self._read_T()
            v, sat_q = self._read_q_V()
            return Reading(float(T), float(v) / self.sensitivity, bool(sat_T or sat_q))
        t_a = self._clock()
        T, sat_T = self._read_T()
        t_b = self._clock()
        v, sat_q = self._read_q_V()
        t_c = self._clock()
        # A single shot samples its input at the centre of its conversion, which ends its read (the
        # thermocouple read converts the cold junction first: its read's midpoint would be 0.55 ms early
        # at 1000 SPS, +1 % on alpha at 5 s). The caller stamps the whole read at (t_a + t_c) / 2.
        mid = 0.5 * (t_a + t_c)
        return Reading(float(T), float(v) / self.sensitivity, bool(sat_T or sat_q),
                       T_dt_s=t_b - self._T_lag_s - mid, q_dt_s=t_c - self._q_lag_s - mid)


def make_sensors(board: Any, sensors_cfg: Any) -> ProbeSensors:
    """Build :class:`ProbeSensors` for the chips named in the ``[sensors]`` config section.

    Probes and configures each chip (SensorFault if one does not answer).

    Parameters
    ----------
    board : Board
        Supplies the I2C bus and the clock the drivers sleep on.
    sensors_cfg : namespace
        The ``[sensors]`` section.

    Returns
    -------
    ProbeSensors
    """
    s = sensors_cfg
    bus, sleep = board.i2c, board.clock.sleep
    if bus is None:
        raise SensorFault("i2c", "not_found", "the board has no I2C bus")
    kw = dict(attempts=s.i2c_attempts, sleep=sleep)
    ads122 = None

    def get_ads122() -> Any:
        # One ADS122C04 can read both sensors: build (and reset) it once.
        nonlocal ads122
        if ads122 is None:
            ads122 = ADS122C04(bus, s.ads122c04_address, on_saturation="flag", **kw)
            ads122.reset()
            ads122.configure(gain=s.ads122c04_gain, data_rate_sps=s.ads122c04_data_rate_sps)
        return ads122

    if s.thermocouple == "mcp9600":
        mcp = MCP9600(bus, s.mcp9600_address, **kw)
        mcp.probe()
        mcp.configure(adc_resolution_bits=s.mcp9600_adc_bits)

        def read_T() -> tuple[float, bool]:
            return mcp.read_hot_junction_C(), False
        T_age_s = mcp.conversion_time_s
        T_lag_s = 0.0  # converts continuously: T_age_s is its reading's age
    else:
        T_age_s = 0.0  # single-shot conversions, read when done
        adc = get_ads122()
        T_lag_s = 0.5 * adc.conversion_time_s

        def read_T() -> tuple[float, bool]:
            t = adc.read_thermocouple_C("AIN0_AIN1", s.ads122c04_gain)
            return t, adc.saturated

    if s.flux_adc == "ads1115":
        ads = ADS1115(bus, s.ads1115_address, on_saturation="flag", **kw)
        ads.configure(mux="AIN0_AIN1", fsr_V=s.ads1115_fsr_V, data_rate_sps=s.ads1115_data_rate_sps)

        def read_q() -> tuple[float, bool]:
            v = ads.read_single_shot_V()
            return v, ads.saturated
        q_lag_s = 0.5 / s.ads1115_data_rate_sps   # a conversion lasts 1 / DR
    else:
        adc2 = get_ads122()

        def read_q() -> tuple[float, bool]:
            v = adc2.read_flux_voltage_V("AIN2_AIN3", s.ads122c04_gain)
            return v, adc2.saturated
        q_lag_s = 0.5 * adc2.conversion_time_s

    return ProbeSensors(read_T, read_q, s.flux_sensitivity_V_per_W_m2, T_age_s=T_age_s,
                        T_resolution_K=thermocouple_resolution_K(s), clock=board.clock.monotonic,
                        T_lag_s=T_lag_s, q_lag_s=q_lag_s,
                        description=f"thermocouple={s.thermocouple} flux={s.flux_adc}")


def thermocouple_resolution_K(sensors_cfg: Any) -> float:
    """Temperature step (K) of the configured thermocouple converter near room temperature.

    Parameters
    ----------
    sensors_cfg : namespace
        The ``[sensors]`` section (the same one :func:`make_sensors` reads).

    Returns
    -------
    float
        One ADC step of thermocouple EMF divided by the type-K Seebeck
        coefficient at 25 °C.
    """
    s = sensors_cfg
    if s.thermocouple == "mcp9600":
        return adc_step_V(int(s.mcp9600_adc_bits)) / TYPE_K_SEEBECK_V_per_K
    return ADS122C04_STEP_V * 128 / s.ads122c04_gain / TYPE_K_SEEBECK_V_per_K
