"""A faithful thermal world: the chips' view of the probe, computed on the (r, z) model.

:class:`FaithfulWorld` is a drop-in for :class:`firmware_sim.world.ThermalWorld`
as the chips and the simulator see it (the :class:`firmware_sim.world_protocol.World`
protocol; the wiring table :mod:`firmware_sim.wiring` connects its signals to the chips),
but where ThermalWorld is the estimator's own idealisation (exact 1-D
Laplace solution of a uniform stack), this one time-steps the axisymmetric
finite-volume model of :mod:`firmware_sim.rz`:

* the probe (PU-foam substrate, heater film of finite area, sensing layer)
  held in air -- natural convection ``h`` on every exposed face, drifting
  back to ambient -- before, between and after touches;
* touches that start when the world is told (possibly seconds before the
  heater is switched on), each with its own contact resistance, object
  temperature and duration, on an object of finite radius and thickness
  (the scene's back boundary; ``"infinite"`` is a thick object);
* touch after touch (``[touch] repeat``, :meth:`FaithfulWorld.repeat_touches`):
  the probe goes down again on a fresh spot ``repeat_gap_s`` after each
  touch and is lifted ``REPEAT_RELEASE_S`` after the next heating ends,
  carrying its own residual heat through the air gap;
* the probe's geometry from :data:`edge.physics.geometry.PROBES` (the
  paper's 55 x 60 mm heater as its equal-area disk, or the small-heater
  probe's 5-mm disk under an overhanging 10 x 10 mm thermopile):
  :func:`geometry_for_probe`, :meth:`FaithfulWorld.for_scene` (``[board]
  probe`` and ``[as_built]`` of a scene);
* the flux sensor as a thermopile inside the sensing layer: the axial flux
  averaged over its depth and its footprint, times its *true* sensitivity --
  the real 10 x 10 mm square (offset, sensitivity map: exact ring weights,
  :mod:`firmware_sim.rz.footprint`) for the small-heater probe and every
  drawn probe, the equal-area disk for the nominal paper probe (whose square
  lies deep inside its heater's uniform flux);
* the thermocouple at its radius (on the axis nominally) at the bottom of the
  sensing layer (probe side of any contact resistance) through a first-order
  bead lag with its *true* time constant;
* the heater film's resistance with a temperature coefficient at constant
  voltage, ``P = d V^2 / (R_0 (1 + alpha_R (T_heater - T_ref)))``;
* as-built deviations (:class:`AsBuilt`, :mod:`firmware_sim.rz.configs`: sensing-layer thickness and
  conductivity, flux sensitivity and footprint, thermocouple position and lag, heater R, TCR and
  lead resistance, the substrate's k, rho c and thickness) that the device is never told; drawn
  per probe by :mod:`firmware_sim.asbuilt`.

Time stepping
-------------
The world marches with virtual time in fixed steps ``dt`` (TR-BDF2, one
banded factorisation per grid configuration and step; configurations --
air, or contact with one touch's resistance and object -- are cached).  The
field is carried from step to step, so nothing is re-superposed.  Within a
step the heater power is constant: the step's electrical energy (the duty
and supply integrated exactly over the step's switching instants) divided
by the step, with ``R(T_heater)`` at the step's start (the one-step lag of
the TCR feedback; ``T_heater`` moves by millikelvin per step).  A contact
switch (touch start or end, ``no_contact`` faults) re-anchors the step grid
at the switch instant: the step before it is shortened to end exactly there
(one extra factorisation per distinct short step).  At a switch the probe's
cells are carried over unchanged (every configuration has the same probe
cells); the object enters at the touch's temperature, or -- after a
``no_contact`` gap within one touch -- as it was left (it is not stepped
while out of contact).  The first step after a switch is marched in
backward-Euler sub-steps of dt/16, dt/16, dt/8, dt/4, dt/2 (monotone and
L-stable: the field's jump at a new interface would make TR-BDF2's first
step swing the face flux negative; the sub-steps also resolve the fast
start of the contact transient).  Four more factorisations per
configuration, cached.

Every step goes through :meth:`firmware_sim.rz.solver.Solver.step`, which recalls a step the
process has already taken from the same field with the same inputs
(:mod:`firmware_sim.rz.stepmemo`: the same bits, no solve; a configuration's factors are built
at its first real solve), so a touch replayed by a later test or a restarted daemon costs no solves.

Outputs between records (step and sub-step ends) are linear
interpolations; the thermocouple lag is integrated exactly on that
piecewise-linear temperature.  A query at a switch instant gets the value
at the end of the step before it (the contact flag is the phase's).

Steps that end after the clock's "now" are provisional: the heater drive
may still change there (the world only knows the duty commanded so far).
Each step keeps its inputs (configuration, electrical energy); on every
query provisional steps are re-checked and, if an input changed, the world
rolls back to a snapshot (kept for the last :data:`SNAPSHOTS` steps) and
re-steps.  New touches and faults roll back likewise; if the snapshot is
gone the world restarts from t = 0 (always correct, only slower).

Verification: ``tests/firmware_sim/rz/test_probe_world.py``,
``tests/firmware_sim/rz/test_probe_world_sessions.py``; speed:
``bench/faithful_world_bench.py``.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections import deque
from operator import attrgetter, itemgetter
from dataclasses import dataclass, field, replace
from typing import Sequence

import numpy as np

from edge.physics.solids import Solid
from firmware_sim.drive import HeaterDrive
from firmware_sim.heater_faults import WORLD_FAULTS, active
from firmware_sim.rz.heater import FilmHeater
from firmware_sim.rz.history import interpolate
from firmware_sim.asbuilt import as_built_for_scene
from firmware_sim.rz.configs import AsBuilt, Geometry, GridConfig, build_config, geometry_for_probe
from firmware_sim.rz.solver import axis_value
from firmware_sim.scene.model import Fault, Scene
from firmware_sim.world_protocol import REPEAT_RELEASE_S, SensorSignals, Truth, WorldState

# AsBuilt, Geometry and their constructors are re-exported: their home was this module.
__all__ = ["AsBuilt", "Geometry", "FaithfulWorld", "Touch", "SNAPSHOTS", "geometry_for_probe", "as_built_for_scene"]

#: Steps kept as roll-back snapshots (each one field copy).
SNAPSHOTS = 48
#: Backward-Euler sub-steps (fractions of dt) that start every phase after a switch.
_STARTUP = (1 / 16, 1 / 16, 1 / 8, 1 / 4, 1 / 2)
_EPS_T = 1e-12
#: Length given to an open repeat touch until a heating closes it (s).
_OPEN_TOUCH_S = 1e6
_start = attrgetter("start_s")   # bisection keys: touches and phases by start, steps by t_a
_first = itemgetter(0)
_second = itemgetter(1)


@dataclass(frozen=True)
class Touch:
    """One contact window with its own contact resistance and object temperature.

    ``end_s`` takes no part in equality: an open repeat touch is the same
    touch (same object, same snapshots) once a heating closes it.
    """

    start_s: float
    end_s: float = field(compare=False)
    contact_resistance_m2K_W: float
    object_temperature_C: float


@dataclass(frozen=True)
class _Phase:
    start_s: float
    end_s: float
    touch: Touch | None   # None: in air


@dataclass
class _State:
    """Everything the march carries from step to step (snapshotted for roll-back)."""

    t: float
    anchor: float          # start of the current phase (steps are anchor + k dt)
    k: int                 # steps taken since the anchor
    key: tuple             # configuration key
    touch: Touch | None    # the touch in progress (None: in air)
    T: np.ndarray          # the field on the configuration's grid
    n_hist: int            # records in the history
    n_steps: int           # steps taken
    objects: dict          # Touch -> object rows left at the last lift (copy-on-write)
    e_in: float            # heater energy so far (J)
    e_lost: float          # heat lost through outer surfaces so far (J)
    e_obj: float           # heat given to objects in closed contact phases (J)
    e_obj0: float          # stored heat of the current object at its entry (J, rel. its touch temperature)

    def copy(self) -> "_State":
        return replace(self, T=self.T.copy())


class FaithfulWorld(SensorSignals, FilmHeater):
    """The probe on the scene's object(s), time-stepped on the (r, z) model.

    Parameters
    ----------
    scene : Scene
    clock : VirtualClock (or any clock with ``now()``)
    drive : HeaterDrive, optional
        Commanded duty (default: none; the heater is off unless a fault turns it on).
    as_built : AsBuilt
        The probe's true deviations from nominal.
    geometry : Geometry
        Substrate, heater/probe/object radii, convection, mesh.
    dt_s : float
        Time step of the march.
    """

    def __init__(self, scene: Scene, clock, drive: HeaterDrive | None = None, *,
                 as_built: AsBuilt = AsBuilt(), geometry: Geometry = Geometry(), dt_s: float = 0.01) -> None:
        if not (dt_s > 0 and math.isfinite(dt_s)):
            raise ValueError("dt_s must be finite and > 0")
        self.scene = scene
        self.clock = clock
        self.drive = drive
        self.as_built = as_built
        # The probe's substrate, thermopile footprint and thermocouple position as built.
        geometry = as_built.apply_to(geometry)
        self.geometry = geometry
        self.dt = float(dt_s)
        nominal = scene.stack
        L_s = nominal.sensing_thickness_m if as_built.sensing_thickness_m is None else as_built.sensing_thickness_m
        m = nominal.material
        k_s = m.k_W_mK if as_built.sensing_k_W_mK is None else as_built.sensing_k_W_mK
        self.sensing_material = Solid(k_W_mK=k_s, rho_kg_m3=m.rho_kg_m3, c_J_kgK=m.c_J_kgK)
        area = nominal.heater_area_m2 if geometry.heater_area_m2 is None else geometry.heater_area_m2
        # As built; the heater film nominal, of the probe's real area.
        self.stack = replace(nominal, sensing_thickness_m=L_s, heater_area_m2=area)
        sens = scene.sensors
        self.flux_sensitivity = (sens.flux_sensitivity_V_per_W_m2 if as_built.flux_sensitivity_V_per_W_m2 is None
                                 else as_built.flux_sensitivity_V_per_W_m2)
        self.tau = (sens.thermocouple_time_constant_s if as_built.thermocouple_time_constant_s is None
                    else as_built.thermocouple_time_constant_s)
        self.R0 = scene.heater.resistance_ohm if as_built.heater_resistance_ohm is None \
            else as_built.heater_resistance_ohm
        self.T_amb = scene.environment.ambient_temperature_C
        self._faults: list[Fault] = [f for f in scene.faults if f.kind in WORLD_FAULTS]
        # Switch times, kept up to date from the drive's new changes (see _switch_times).
        self._drive_rev = None
        self._drive_times: set[float] = set()
        self._sw: np.ndarray | None = None
        self._sw_faults = -1
        self._touches: list[Touch] = [Touch(scene.touch.start_s, scene.touch.end_s,
                                            scene.touch_contact_resistance_m2K_W, scene.object_temperature_C)]
        #: Whether the last touch is an open repeat touch (``[touch] repeat``, :meth:`repeat_touches`).
        self._repeat_open = False
        self._configs: dict[tuple, GridConfig] = {}
        self._phases: list[_Phase] | None = None
        # History: one record per step end, plus one more at each switch (its right-hand side).
        self._cap = 0
        self._h: dict[str, np.ndarray] = {}
        self._steps: list[tuple] = []       # (t_a, t_b, phase, E_nominal (J ohm), R used (ohm))
        self._p0 = 0                        # first step that may still change (ends after "now")
        self._snaps: deque[tuple[int, _State]] = deque(maxlen=SNAPSHOTS)
        self._restart()
        if scene.touch.repeat:
            self._open_repeat(scene.touch.end_s)

    @classmethod
    def for_scene(cls, scene: Scene, clock, drive: HeaterDrive | None = None, *, dt_s: float = 0.01,
                  **geometry: object) -> "FaithfulWorld":
        """The world a scene describes: its ``[board] probe`` geometry and its ``[as_built]`` deviations.

        ``geometry`` overrides fields of the probe's :class:`Geometry` (see :func:`geometry_for_probe`).
        """
        return cls(scene, clock, drive, as_built=as_built_for_scene(scene),
                   geometry=geometry_for_probe(scene.board.probe, **geometry), dt_s=dt_s)

    # ------------------------------------------------------------------ configuration

    def _grid(self, key: tuple) -> GridConfig:
        cfg = self._configs.get(key)
        if cfg is None:
            cfg = build_config(key, self.scene, self.geometry, self.stack, self.sensing_material, self.T_amb,
                               self.dt, next(iter(self._configs.values()), None))
            self._configs[key] = cfg
        return cfg

    def _key(self, phase: _Phase) -> tuple:
        if phase.touch is None:
            return ("air",)
        t = phase.touch
        return ("contact", t.contact_resistance_m2K_W, t.object_temperature_C)

    # ------------------------------------------------------------------ faults

    @property
    def faults(self) -> tuple[Fault, ...]:
        """Faults the world models (bus faults live on the SimBus)."""
        return tuple(self._faults)

    def add_fault(self, fault: Fault, *, now_s: float | None = None) -> None:
        """Add a fault; it may not start before the current virtual time (see ThermalWorld.add_fault)."""
        if fault.kind not in WORLD_FAULTS:
            raise ValueError(f"fault kind {fault.kind!r} is not modelled by the thermal world")
        now = self.clock.now() if now_s is None else min(float(now_s), self.clock.now())
        if fault.at_s < now - 1e-12:
            raise ValueError(f"fault at_s={fault.at_s} s is in the past (now {now} s)")
        self._faults.append(fault)
        self._phases = None
        self._invalidate_from(fault.at_s)

    def _active(self, kind: str, t_s: float) -> list[Fault]:
        return active(self._faults, kind, t_s)

    # ------------------------------------------------------------------ touches and phases

    @property
    def touches(self) -> tuple[tuple[float, float], ...]:
        """Contact windows ``(start_s, end_s)``."""
        return tuple((t.start_s, t.end_s) for t in self._touches)

    @property
    def touch_specs(self) -> tuple[Touch, ...]:
        return tuple(self._touches)

    def add_touch(self, start_s: float, length_s: float, *, contact_resistance_m2K_W: float | None = None,
                  object_temperature_C: float | None = None) -> None:
        """Put the probe on an object for ``[start_s, start_s + length_s)``.

        Each touch has its own contact resistance and object temperature
        (defaults: the scene's); the object is a fresh one at that temperature.
        """
        start, length = float(start_s), float(length_s)
        if not start >= self.clock.now() - 1e-12:
            raise ValueError(f"start_s={start_s} s is in the past (now {self.clock.now()} s)")
        if not (length > 0 and math.isfinite(length)):
            raise ValueError(f"length_s must be a finite number > 0, got {length_s!r}")
        rc = self.scene.touch_contact_resistance_m2K_W if contact_resistance_m2K_W is None else float(
            contact_resistance_m2K_W)
        if not (rc >= 0 and math.isfinite(rc)):
            raise ValueError("contact_resistance_m2K_W must be finite and >= 0")
        T_o = self.scene.object_temperature_C if object_temperature_C is None else float(object_temperature_C)
        end = start + length
        if self._repeat_open:
            # Touches placed by hand take over from the scene's touch after touch (as in ThermalWorld).
            self._touches.pop()
            self._repeat_open = False
            self._phases = None
            self._invalidate_from(self.clock.now())
        for t in self._touches:
            if start < t.end_s and t.start_s < end:
                raise ValueError(f"touch [{start}, {end}) s overlaps the touch [{t.start_s}, {t.end_s}) s")
        self._touches.append(Touch(start, end, rc, T_o))
        self._touches.sort(key=lambda t: t.start_s)
        self._phases = None
        self._invalidate_from(start)

    def contact_at(self, t_s: float) -> bool:
        """Whether the probe touches an object at ``t_s``."""
        self._sync_repeat(self._switch_times())
        return self._touch_at(t_s) is not None

    # ---- touch after touch

    def repeat_touches(self) -> None:
        """Touch after touch from now on (what ``[touch] repeat = true`` does; no-op if already on).

        ``[touch] repeat_gap_s`` after each touch the probe is put down again
        -- on a fresh spot of the object, at the touch's temperature and
        contact resistance -- and stays until ``REPEAT_RELEASE_S`` after the
        next heating ends; in between it hangs in air, carrying what heat
        the last touch left in it (as :class:`firmware_sim.world.ThermalWorld`
        does, without its uniform-probe approximation).
        """
        if self._repeat_open:
            return
        self._open_repeat(max(self._touches[-1].end_s if self._touches else 0.0, self.clock.now()))

    def _open_repeat(self, after_s: float) -> None:
        """Put the probe down again ``repeat_gap_s`` after ``after_s``, until a heating closes the touch."""
        start = after_s + self.scene.touch.repeat_gap_s
        self._touches.append(Touch(start, start + _OPEN_TOUCH_S, self.scene.touch_contact_resistance_m2K_W,
                                   self.scene.object_temperature_C))
        self._repeat_open = True
        self._phases = None
        self._invalidate_from(start)

    def _sync_repeat(self, switches: np.ndarray) -> None:
        """Close the open repeat touch at the first heater switch-off inside it (and open the next).

        Every read syncs first, so the switch-off (at or before "now") is
        learnt before any value after it is handed out; the new edges lie
        ``REPEAT_RELEASE_S`` after it, so only provisional steps are redone.
        """
        if not self._repeat_open or self.drive is None:
            return
        open_t = self._touches[-1]
        d = self.drive
        for x in switches[np.searchsorted(switches, open_t.start_s, side="right"):]:
            x = float(x)
            if d.duty_at(x) <= 0 < d.duty_at(x - 1e-9):
                end = x + REPEAT_RELEASE_S
                self._touches[-1] = replace(open_t, end_s=end)
                self._phases = None
                self._invalidate_from(end)
                self._open_repeat(end)
                return

    def _touch_at(self, t_s: float) -> Touch | None:
        if self._active("no_contact", t_s):
            return None
        # Touches are sorted and disjoint: a bisection, so a long session costs no more per query.
        i = bisect_right(self._touches, t_s, key=_start) - 1
        if i >= 0 and t_s < self._touches[i].end_s:
            return self._touches[i]
        return None

    def phases(self) -> list[_Phase]:
        """Air / contact phases covering [0, inf)."""
        if self._phases is not None:
            return self._phases
        edges = {0.0}
        for t in self._touches:
            edges.update((t.start_s, t.end_s))
        for f in self._faults:
            if f.kind == "no_contact":
                edges.add(f.at_s)
                if f.until_s is not None:
                    edges.add(f.until_s)
        el = sorted(edges) + [math.inf]
        out: list[_Phase] = []
        for a, b in zip(el[:-1], el[1:]):
            c = self._touch_at(a)
            if out and out[-1].touch == c:
                out[-1] = _Phase(out[-1].start_s, b, c)
            else:
                out.append(_Phase(a, b, c))
        self._phases = out
        return out

    def _phase_at(self, t: float) -> _Phase:
        ph = self.phases()
        return ph[max(bisect_right(ph, t, key=_start) - 1, 0)]

    # ------------------------------------------------------------------ the march

    _FIELDS = ("t", "T_tc", "q_sensor", "q_face", "T_heater", "T_obj_face", "y", "contact", "power",
               "e_in", "e_lost", "e_stored")

    def _restart(self) -> None:
        """Back to t = 0: the probe at ambient, in whatever phase t = 0 is."""
        ph = self._phase_at(0.0)
        key = self._key(ph)
        cfg = self._grid(key)
        T = np.full(cfg.grid.shape, self.T_amb)
        objects: dict = {}
        self._h = {}
        self._cap = 0
        self._steps = []
        self._p0 = 0
        self._snaps.clear()
        self._state = _State(t=0.0, anchor=0.0, k=0, key=key, touch=ph.touch, T=T * cfg.grid.active, n_hist=0,
                             n_steps=0, objects=objects, e_in=0.0, e_lost=0.0, e_obj=0.0, e_obj0=0.0)
        if cfg.has_object:
            self._enter_object(cfg, ph.touch)
        self._record(cfg, power=0.0)

    def _enter_object(self, cfg: GridConfig, touch: Touch) -> None:
        st = self._state
        stored = st.objects.get(touch)
        T_o = touch.object_temperature_C
        if stored is None:
            st.T[cfg.obj_rows] = T_o
        else:
            st.T[cfg.obj_rows] = stored
        st.T *= cfg.grid.active
        st.e_obj0 = self._object_heat(cfg, st.T, T_o)

    def _object_heat(self, cfg: GridConfig, T: np.ndarray, T_o: float) -> float:
        C = cfg.grid.cap_J_K[cfg.obj_rows]
        return float(np.sum(C * (T[cfg.obj_rows] - T_o)))

    def _probe_heat(self, cfg: GridConfig, T: np.ndarray) -> float:
        C = cfg.grid.cap_J_K[: cfg.n_probe_rows]
        return float(np.sum(C * (T[: cfg.n_probe_rows] - self.T_amb)))

    def _grow(self) -> None:
        cap = max(1024, 2 * self._cap)
        for name in self._FIELDS:
            old = self._h.get(name)
            new = np.zeros(cap)
            if old is not None:
                new[: self._cap] = old[: self._cap]
            self._h[name] = new
        self._cap = cap

    def _record(self, cfg: GridConfig, power: float, y: float | None = None, read: np.ndarray | None = None) -> None:
        """Append the state's history row; ``read``: the probes' values of this field, if already read."""
        st = self._state
        if st.n_hist >= self._cap:
            self._grow()
        if read is None:
            s = cfg.solver(self.dt)
            read = s.probes.read(st.T, s.g_t)
        T_tc, q_s, q_f = read
        i = st.n_hist
        h = self._h
        h["t"][i] = st.t
        h["T_tc"][i] = T_tc
        h["q_sensor"][i] = q_s
        h["q_face"][i] = q_f
        h["T_heater"][i] = float(np.sum(cfg.heater_w * st.T))
        if cfg.has_object:
            # Object-side face temperature on the axis: top object cells + half-cell drop, r^2 fit.
            j = cfg.n_probe_rows
            gz, A, dz, c = cfg.face_terms    # the grid's arrays, taken once per configuration
            q_ax = gz * (st.T[j - 1, :2] - st.T[j, :2]) / A
            h["T_obj_face"][i] = float(axis_value(cfg.grid, st.T[j, :2] + q_ax * dz / (2 * cfg.k_obj), c))
        else:
            h["T_obj_face"][i] = np.nan
        h["y"][i] = T_tc if y is None else y
        h["contact"][i] = 1.0 if cfg.has_object else 0.0
        h["power"][i] = power
        h["e_in"][i] = st.e_in
        h["e_lost"][i] = st.e_lost
        h["e_stored"][i] = self._probe_heat(cfg, st.T) + st.e_obj + (
            self._object_heat(cfg, st.T, st.touch.object_temperature_C) - st.e_obj0 if cfg.has_object else 0.0)
        st.n_hist = i + 1

    def _lag(self, y0: float, T0: float, T1: float, dt: float) -> float:
        """First-order lag ``tau y' + y = T`` over a step with T linear from T0 to T1."""
        if self.tau <= 0:
            return T1
        if dt <= 0:
            return y0
        m = (T1 - T0) / dt
        a = math.exp(-dt / self.tau)
        return T1 - m * self.tau + (y0 - T0 + m * self.tau) * a

    def _step(self, switches: np.ndarray, now: float) -> None:
        st = self._state
        ph = self._phase_at(st.t)
        cfg = self._grid(st.key)
        t_a = st.t
        t_b = st.anchor + (st.k + 1) * self.dt
        switch = t_b >= ph.end_s - 1e-9 * self.dt
        if switch:
            t_b = ph.end_s
        dt = t_b - t_a
        e_nom = self._nominal_energy(t_a, t_b, switches)
        self._snaps.append((st.n_steps, st.copy()))
        T_h = float(np.sum(cfg.heater_w * st.T))
        R = self.resistance_ohm(T_h)
        self._steps.append((t_a, t_b, ph, e_nom, R))
        power = self._film_power(e_nom / dt, R) if e_nom else 0.0
        if st.k == 0 and (st.t > 0 or cfg.has_object) and abs(dt - self.dt) <= 1e-12 * self.dt:
            # First step of a phase: the field jumps at the new interface (contact) or at the
            # newly exposed face (lift); march it with L-stable, monotone backward-Euler
            # sub-steps growing from dt/16 (no negative flux, no ringing of the thin cells),
            # which also resolves the fast start of the contact transient.
            subs, scheme = [dt * f for f in _STARTUP], "be"
        else:
            subs, scheme = [dt], "trbdf2"
        h = self._h
        t = t_a
        for n, d in enumerate(subs):
            s = cfg.solver(d, scheme)
            st.T, e_in, e_lost = s.step(st.T, cfg.src, power)
            n_prev = st.n_hist - 1
            st.t = t = t_b if n == len(subs) - 1 else t + d
            st.e_in += e_in
            st.e_lost += e_lost
            read = s.probes.read(st.T, s.g_t)
            y = self._lag(h["y"][n_prev], h["T_tc"][n_prev], float(read[0]), d)
            self._record(cfg, power, y, read)
        st.k += 1
        st.n_steps += 1
        if switch:
            self._switch(cfg)
        if self._p0 == st.n_steps - 1 and t_b <= now:
            self._p0 = st.n_steps

    def _switch(self, old: GridConfig) -> None:
        """Change configuration at the current time (a phase boundary)."""
        st = self._state
        ph = self._phase_at(st.t)
        key = self._key(ph)
        new = self._grid(key)
        if old.has_object:
            st.e_obj += self._object_heat(old, st.T, st.touch.object_temperature_C) - st.e_obj0
            st.objects = dict(st.objects)
            st.objects[st.touch] = st.T[old.obj_rows].copy()
        T = np.full(new.grid.shape, self.T_amb)
        T[: new.n_probe_rows] = st.T[: old.n_probe_rows]
        st.T = T * new.grid.active
        st.key, st.touch, st.anchor, st.k = key, ph.touch, st.t, 0
        if new.has_object:
            self._enter_object(new, ph.touch)
        # No record here: the step's end (the left side) is the record at the switch, and the
        # start-up sub-steps resolve the jump; the ledger's stored heat is continuous across
        # (the probe's cells are carried over, the object's heat is booked from its entry).

    def _invalidate_from(self, t_s: float) -> None:
        """Drop everything computed on or after ``t_s`` (a step that ends after it is redone)."""
        i = bisect_right(self._steps, t_s + _EPS_T, key=_second)   # the first step ending after t_s
        if i < len(self._steps):
            self._rollback(i)

    def _rollback(self, i: int) -> None:
        for n, snap in reversed(self._snaps):
            if n == i:
                self._state = snap.copy()
                # Snapshots taken before a touch was added hold the old configuration keys; re-derive it.
                del self._steps[i:]
                self._snaps = deque((s for s in self._snaps if s[0] < i), maxlen=SNAPSHOTS)
                self._p0 = min(self._p0, i)
                if self._phase_at(self._state.t).touch != self._state.touch:
                    self._restart()    # the phase at the snapshot changed under it: start over
                return
        self._restart()

    def _revalidate(self, switches: np.ndarray, now: float) -> None:
        """Re-check provisional steps' inputs; roll back to the first that changed."""
        i = self._p0
        while i < len(self._steps):
            t_a, t_b, ph, e_nom, _ = self._steps[i]
            if self._phase_at(t_a) != ph or self._nominal_energy(t_a, t_b, switches) != e_nom:
                self._rollback(i)
                break
            if t_b <= now and i == self._p0:
                self._p0 = i + 1
            i += 1

    def _advance_to(self, t: float) -> None:
        now = self.clock.now()
        switches = self._switch_times()
        self._sync_repeat(switches)
        self._revalidate(switches, now)
        while self._state.t < t - 1e-12:
            self._step(switches, now)

    # ------------------------------------------------------------------ read-outs

    def _interp(self, ts: np.ndarray, names: Sequence[str]) -> dict[str, np.ndarray]:
        if ts.size == 0:
            return {n: np.zeros(0) for n in names} | {"y": np.zeros(0)}
        # A chip's one sample: checked and reached on the scalar, not with array calls.
        last = ts.reshape(-1)[0] if ts.size == 1 else ts.max()
        if (not last >= 0.0) if ts.size == 1 else np.any(~(ts >= 0.0)):
            raise ValueError(f"t_s must be >= 0, got {ts[~(ts >= 0.0)][0]!r}")
        self._advance_to(float(last))
        return interpolate(self._h, self._state.n_hist, ts, names, self.tau)

    def state(self, t_s: float) -> WorldState:
        """The world at virtual time ``t_s`` (>= 0)."""
        t = float(t_s)
        if not t >= 0.0:
            raise ValueError(f"t_s must be >= 0, got {t_s!r}")
        v = self._interp(np.array([t]), ("T_tc", "q_face"))
        return WorldState(t, float(v["T_tc"][0]), float(v["y"][0]), float(v["q_face"][0]), self.contact_at(t))

    def truth(self, t_s: Sequence[float]) -> Truth:
        """Series at times ``t_s`` (s): surface (probe-side face on the axis), thermocouple, face flux."""
        t = np.asarray(t_s, dtype=float).ravel()
        v = self._interp(t, ("T_tc", "q_face"))
        # _interp synced the repeat touches: the contact flags can be read directly.
        return Truth(t, v["T_tc"], v["y"], v["q_face"], np.array([self._touch_at(x) is not None for x in t], dtype=bool),
                     np.array([self.q_v_at(x) for x in t]))

    def series(self, t_s: Sequence[float]) -> dict[str, np.ndarray]:
        """Every recorded quantity at ``t_s``: T_tc (no lag), thermocouple ("y"), q_sensor, q_face, T_heater,
        T_obj_face (object side of the interface on the axis, NaN in air), power, energies."""
        t = np.asarray(t_s, dtype=float).ravel()
        return self._interp(t, self._FIELDS[1:6] + ("power", "e_in", "e_lost", "e_stored"))

    def _resistance_in_step(self, t: float) -> float:
        """Film resistance the march used in the step containing ``t`` (R at the step's start)."""
        self._advance_to(t + 1e-9)
        i = max(bisect_right(self._steps, t, key=_first) - 1, 0)
        return self._steps[i][4]

    def thermopile_W_m2(self, t_s: float) -> float:
        """What the thermopile integrates: axial flux averaged over its depth and area (W/m^2)."""
        return float(self._interp(np.array([float(t_s)]), ("q_sensor",))["q_sensor"][0])

    def energy_ledger(self, t_s: float | None = None) -> dict[str, float]:
        """Heater energy in, heat lost through surfaces, heat stored (probe + objects), J, at a step end."""
        t = self.clock.now() if t_s is None else float(t_s)
        self._advance_to(t)
        n = self._state.n_hist
        i = int(np.searchsorted(self._h["t"][:n], t, side="right")) - 1
        e = {k: float(self._h[k][i]) for k in ("e_in", "e_lost", "e_stored")}
        e["t_s"] = float(self._h["t"][i])
        e["residual"] = e["e_in"] - e["e_lost"] - e["e_stored"]
        return e

    # ------------------------------------------------------------------ signals (the World protocol)

    def thermocouple_C(self, t_s: float, *, stream: str = "") -> float:
        """Hot-junction temperature (°C) the thermocouple reports at ``t_s`` (true bead lag).

        ``stream`` is ignored: the world marches in time and has no per-caller look-ahead.
        """
        return float(self._interp(np.array([float(t_s)]), ())["y"][0])

    def cold_junction_C(self, t_s: float) -> float:
        """Board (cold-junction, ADC die) temperature (°C)."""
        return self.T_amb

    def sensed_flux_W_m2(self, t_s: float, *, stream: str = "") -> float:
        """What the thermopile integrates (W/m^2; ``stream`` is ignored): :meth:`thermopile_W_m2`."""
        return self.thermopile_W_m2(t_s)

    @property
    def flux_sensitivity_V_per_W_m2(self) -> float:
        """The thermopile's true sensitivity (V per W/m^2; as built, the device is never told)."""
        return self.flux_sensitivity
