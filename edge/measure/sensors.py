"""The probe's two sensors -- thermocouple and heat-flux sensor -- as one reading source.

:func:`make_sensors` builds :class:`ProbeSensors` from the ``[sensors]``
configuration section: it probes and configures the converter chips through
the board's I2C bus and wraps them in two read functions.
:func:`thermocouple_resolution_K` (from :mod:`edge.hw.chips`) gives the
temperature step of the same configured converter, which the estimator
carries into its uncertainty.

Nothing here names a chip: the chips are described in :mod:`edge.hw.chips`
and reached through the board; nothing here imports the simulator.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

from edge.hw import chips
from edge.hw.chips import RoleReader, thermocouple_resolution_K
from edge.hw.faults import SensorFault

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

    The section names a chip for each role (``thermocouple``, ``flux_adc``);
    each is opened (probed and configured) once through its entry in
    :data:`edge.hw.chips.CHIPS`, even when one chip plays both roles, and
    read through the entry's role readers. SensorFault if a chip does not
    answer.

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
    devices: dict[str, Any] = {}

    def reader(role: str, name: str) -> RoleReader:
        spec = chips.chip(name)
        if role not in spec.roles:
            raise ValueError(f"{spec.part} cannot read the {role}; chips that can: {chips.names_for(role)}")
        st = chips.chip_settings(spec, s)
        if name not in devices:     # one chip may play both roles: open (and reset) it once
            devices[name] = spec.open(bus, st, attempts=s.i2c_attempts, sleep=sleep, clock=board.clock.monotonic)
        return spec.readers[role](devices[name], st)

    T = reader(chips.THERMOCOUPLE, s.thermocouple)
    q = reader(chips.FLUX, s.flux_adc)
    return ProbeSensors(T.read, q.read, s.flux_sensitivity_V_per_W_m2, T_age_s=T.age_s,
                        T_resolution_K=thermocouple_resolution_K(s), clock=board.clock.monotonic,
                        T_lag_s=T.lag_s, q_lag_s=q.lag_s,
                        description=f"thermocouple={s.thermocouple} flux={s.flux_adc}")
