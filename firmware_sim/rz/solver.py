"""Transient conduction on an (r, z) :class:`~firmware_sim.rz.grid.Grid`, unconditionally stable.

The semi-discrete system is ``C dT/dt = -K T + g + p(t) Q``: ``C`` the cell
capacities, ``K`` the (symmetric) conductance matrix with the outer-surface
conductances on its diagonal, ``g`` their ambient forcing, ``Q`` a per-cell
source pattern (W per unit amplitude) and ``p(t)`` its amplitude, constant
over each time step (the heater's PWM is piecewise constant and its switching
instants fall on steps).  Schemes:

* ``"be"``: backward Euler, first order, L-stable;
* ``"cn"``: Crank-Nicolson, second order, A-stable but not L-stable: the
  stiff modes (the thin cells at the interfaces) ring after a jump, so it
  starts with Rannacher smoothing (two backward-Euler half steps, the same
  matrix);
* ``"trbdf2"`` (default): TR-BDF2 with gamma = 2 - sqrt(2) (Bank et al. 1985),
  second order and L-stable, so the contact transient (a jump of T at the
  interface) is damped, not echoed.

Each scheme solves ``(C / tau + K) x = b`` with one ``tau`` (for TR-BDF2 the
two stages share ``tau = (1 - 1/sqrt 2) dt``), so one factorisation per
(grid, dt, scheme) serves every step.  The solver is block tridiagonal in the
ordering with the shorter grid direction inside a block: block Gaussian
elimination of a banded matrix whose bandwidth is the block size, the fill
inside the band kept as dense Schur-complement inverses.  Per step that is
two dense block mat-vecs per block row -- NumPy only.

Outputs per step (:class:`Record`, :class:`Probes`): thermocouple, flux
sensor and the flux into the object's face.  Everything is linear in the
initial and ambient temperatures and the source amplitude, so a heater run is
the free response plus the unit-step response superposed over the power
changes (:meth:`Solver.superpose`), exactly as a direct run.
"""

from __future__ import annotations

import hashlib
import math
import struct
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from firmware_sim.rz.blocktri import BlockTridiagonal, clear_row_cache
from firmware_sim.rz.footprint import depth_weights, off_axis_weights
from firmware_sim.rz.grid import Grid
from firmware_sim.rz.stepmemo import clear_step_memo, keep, recall

__all__ = ["BlockTridiagonal", "clear_factor_cache", "Probes", "Record", "Solver", "steady_state", "axis_value",
           "axis_weights", "SCHEMES"]

SCHEMES = ("be", "cn", "trbdf2")
_GAMMA = 2.0 - math.sqrt(2.0)
_W = (1.0 - _GAMMA) / (2.0 - _GAMMA)  # BDF2-stage weight; equals _GAMMA / 2 for this gamma
# BDF2 stage's combination of the step's start and the TR stage: T_g / (g (2-g)) - (1-g)^2 / (g (2-g)) T.
_BDF2_A = 1.0 / (_GAMMA * (2.0 - _GAMMA))
_BDF2_C = (1.0 - _GAMMA) ** 2 / (_GAMMA * (2.0 - _GAMMA))


# ----------------------------------------------------------------------------------------------
# Shared factors


#: Factors shared by every solver of the same matrix (worlds rebuilt for the same probe, scene and
#: step: a session's touches, a simulator per measurement), least recently used dropped first.
_FACTOR_CACHE: OrderedDict[bytes, BlockTridiagonal] = OrderedDict()
_FACTOR_CACHE_BYTES = 128 * 2**20  # ~20 factors of 6.6 MB (the paper probe's 121 x 75 grid), 13 of the small-heater probe's


def clear_factor_cache() -> None:
    """Forget the shared factors, block rows and memoised steps (a benchmark that times a cold start calls it first)."""
    _FACTOR_CACHE.clear()
    clear_row_cache()
    clear_step_memo()


def _factor(diag: np.ndarray, off_in: np.ndarray, off_between: np.ndarray,
            shared_rows: int | None = None) -> BlockTridiagonal:
    """:class:`BlockTridiagonal` of these arrays, from the cache when the very same matrix was factored.

    The key is a digest of the arrays' shapes and exact bytes, so a hit is the factor the
    arrays would give (the factor is read-only once built; ``shared_rows``, which rows it may
    share with other factors, does not change it).
    """
    h = hashlib.blake2b(digest_size=20)
    for a in (diag, off_in, off_between):
        a = np.ascontiguousarray(a, dtype=float)
        h.update(repr(a.shape).encode())
        h.update(a.tobytes())
    key = h.digest()
    fac = _FACTOR_CACHE.get(key)
    if fac is not None:
        _FACTOR_CACHE.move_to_end(key)
        return fac
    fac = BlockTridiagonal(diag, off_in, off_between, shared_rows)
    _FACTOR_CACHE[key] = fac
    total = sum(f.nbytes for f in _FACTOR_CACHE.values())
    while total > _FACTOR_CACHE_BYTES and len(_FACTOR_CACHE) > 1:
        _, old = _FACTOR_CACHE.popitem(last=False)
        total -= old.nbytes
    return fac


class _Operator:
    """``K`` of the grid as stencil arrays, in a chosen block orientation."""

    def __init__(self, grid: Grid) -> None:
        self.grid = grid
        # Blocks along the shorter direction: the band is min(nr, nz) wide.
        self.transpose = grid.nr > grid.nz
        self.cap = grid.cap_J_K
        self.gr, self.gz, self.gb = grid.g_r_W_K, grid.g_z_W_K, grid.g_b_W_K
        kd = self.gb.copy()
        kd[:, :-1] += self.gr
        kd[:, 1:] += self.gr
        kd[:-1] += self.gz
        kd[1:] += self.gz
        self.k_diag = kd
        # Inactive cells are decoupled; give them a unit diagonal so the system stays SPD.
        self.inactive = ~grid.active
        # Block rows another configuration can share (blocktri._ROW_CACHE): a probe's rows above its
        # object, the same on every object it touches at the same step.  An object's rows belong to
        # one configuration (its whole factor is cached as such), and blocks across the layers (the
        # transposed orientation) hold every layer's cells: none of those is kept for sharing.
        names = [layer.name for layer in grid.layers]
        if "object" not in names:
            self.shared_rows = None
        elif self.transpose:
            self.shared_rows = 0
        else:
            self.shared_rows = int(np.argmax(grid.layer_of_row == names.index("object")))

    def apply_K(self, T: np.ndarray) -> np.ndarray:
        """``K @ T`` for a field of the grid's shape (conduction out of each cell + surface loss)."""
        out = self.k_diag * T
        out[:, :-1] -= self.gr * T[:, 1:]
        out[:, 1:] -= self.gr * T[:, :-1]
        out[:-1] -= self.gz * T[1:]
        out[1:] -= self.gz * T[:-1]
        return out

    def factor(self, inv_tau: float) -> BlockTridiagonal:
        """Factor of ``C / tau + K`` (``inv_tau = 0``: the steady operator ``K``)."""
        d = self.cap * inv_tau + self.k_diag
        d = np.where(self.inactive, 1.0, d)
        off_r, off_z = -self.gr, -self.gz
        if self.transpose:
            return _factor(d.T.copy(), off_z.T.copy(), off_r.T.copy(), self.shared_rows)
        return _factor(d, off_r, off_z, self.shared_rows)

    def solve(self, fac: BlockTridiagonal, rhs: np.ndarray) -> np.ndarray:
        if self.transpose:
            return fac.solve(rhs.T).T
        return fac.solve(rhs)


# ----------------------------------------------------------------------------------------------
# Outputs


@dataclass(frozen=True)
class Probes:
    """Linear read-outs of a field: ``value = w . T[idx] + w_g . (g T_inf)[idx_g]``.

    ``idx``/``w`` hold, per output, the pair (cells, weights) on T followed by
    the pair on the ambient forcing (non-empty only where an output uses an
    outer surface's flux, i.e. no object under the probe).

    ``T_tc``: thermocouple at the bottom of the sensing layer (probe side of any
    contact resistance; on the axis, or at ``meta`` ``thermocouple_r_m`` and
    ``thermocouple_height_m`` above it), ``q_sensor``: flux sensor, ``q_face``:
    flux into the object's face (or out of the sensing layer's bottom surface
    without an object), both over the sensor's footprint (its disk, or ``meta``
    ``sensor_ring_weights``), positive downwards (probe to object).
    """

    idx: tuple[np.ndarray, ...]
    w: tuple[np.ndarray, ...]
    names: tuple[str, ...] = ("T_tc", "q_sensor", "q_face")

    def read(self, T: np.ndarray, g_t: np.ndarray) -> np.ndarray:
        """Values for field ``T`` (flattened or not) and ambient term vector ``g_t`` (=sum g T_inf)."""
        flat, g = T.reshape(-1), g_t.reshape(-1)
        idx, w = self.idx, self.w
        # Per output its dot on T plus its dot on the forcing (the same scalar sums an array add makes).
        return np.array([flat[i] @ a + g[k] @ b for i, a, k, b in zip(idx[::2], w[::2], idx[1::2], w[1::2])])


def _axis_weights(grid: Grid) -> tuple[float, float]:
    """Weights of the first two columns that extrapolate a field to the axis.

    The field is even in r, ``T = a + b r^2`` near the axis; fitting that
    through the two cells' mean ``r^2`` (exact for the profile) gives the
    axis value to O(dr^4) where the axis cell alone is off by O(dr^2).
    """
    r = grid.r_faces_m
    rho = 0.5 * (r[1:3] ** 2 + r[0:2] ** 2)
    return rho[1] / (rho[1] - rho[0]), -rho[0] / (rho[1] - rho[0])


def axis_weights(grid: Grid) -> tuple[float, float]:
    """The weights :func:`axis_value` gives the first two cells (for a caller that reads many profiles)."""
    return _axis_weights(grid)


def axis_value(grid: Grid, values: np.ndarray, weights: tuple[float, float] | None = None) -> float | np.ndarray:
    """Axis value of a radial profile (last axis indexed by r), from its first two cells.

    ``weights``: :func:`axis_weights` of ``grid`` if already taken.
    """
    c0, c1 = _axis_weights(grid) if weights is None else weights
    v = np.asarray(values, float)
    return c0 * v[..., 0] + c1 * v[..., 1]


def _probes(grid: Grid) -> Probes:
    """Weights of the three outputs (see :class:`Probes`) for a probe grid."""
    meta = grid.meta
    nz, nr = grid.shape
    rows = grid.rows_of("sensing")
    j_s = rows[-1]                      # last row of the sensing layer
    has_obj = j_s + 1 < nz and grid.layer_of_row[j_s + 1] != grid.layer_of_row[j_s]
    dz = grid.dz_m
    k_s = grid.k_cell_W_mK[j_s, 0]
    area = grid.ring_area_m2  # a property that builds the whole array: once, not per ring and face

    def flat(j, i):
        return j * nr + i

    # Flux through the bottom face of cell (j_s, i), W/m^2, as weights on T (and on g T_inf).
    def bottom_flux(i):
        A = area[i]
        if has_obj:
            g = grid.g_z_W_K[j_s, i]
            return [flat(j_s, i), flat(j_s + 1, i)], [g / A, -g / A], [], []
        g = grid.g_b_W_K[j_s, i]  # the bottom face is the cell's only outer face on the axis rows
        return [flat(j_s, i)], [g / A], [flat(j_s, i)], [-1.0 / A]

    # Thermocouple: probe-side face temperature T_c - q dz/(2k) in the first two columns,
    # then the even extrapolation to the axis, T(r) = a + b r^2, through the cells' mean r^2
    # (see _axis_weights).
    tc_i, tc_w, tc_gi, tc_gw = [], [], [], []
    r_tc, h_tc = float(meta.get("thermocouple_r_m", 0.0)), float(meta.get("thermocouple_height_m", 0.0))
    lever = 0.5 * dz[j_s] - h_tc   # from the last cell's centre down to the junction
    for i, c in (zip((0, 1), _axis_weights(grid)) if r_tc <= 0.0 else off_axis_weights(grid.r_faces_m, r_tc)):
        if lever < 0:   # the junction lies above the last cell's centre: linear between two centres
            j, f = depth_weights(grid.z_centres_m[rows], float(grid.z_faces_m[j_s + 1]) - h_tc)
            tc_i += [flat(rows[j], i), flat(rows[j + 1], i)]
            tc_w += [c * (1.0 - f), c * f]
            continue
        fi, fw, gi, gw = bottom_flux(i)
        tc_i += [flat(j_s, i)] + fi
        tc_gi += gi
        if h_tc == 0.0:   # (the same expression as ever: nominal probes read bit for bit as before)
            tc_w += [c] + [-c * w * 0.5 * dz[j_s] / k_s for w in fw]
            tc_gw += [-c * w * 0.5 * dz[j_s] / k_s for w in gw]
        else:
            tc_w += [c] + [-c * w * lever / k_s for w in fw]
            tc_gw += [-c * w * lever / k_s for w in gw]

    # Flux sensor: trapezoid in z over the face fluxes of its depth range, area mean over its footprint:
    # the real one's share of each ring (firmware_sim.rz.footprint) when the grid carries it, else its disk.
    n_s = grid.r_index_below(meta["sensor_radius_m"])
    rw = meta.get("sensor_ring_weights")
    ring_w = area[:n_s] / (math.pi * grid.r_faces_m[n_s] ** 2) if rw is None else np.asarray(rw)[:n_s] / np.sum(rw)
    z0, z1 = meta["sensor_z_m"]
    f0, f1 = grid.z_index_of(z0), grid.z_index_of(z1)
    qs_i, qs_w = [], []
    qs_gi, qs_gw = [], []
    for f in range(f0, f1 + 1):  # faces f between rows f-1 and f
        wz = (0.5 * (dz[f - 1] if f > f0 else 0.0) + 0.5 * (dz[f] if f < f1 else 0.0)) / (z1 - z0)
        for i, wa in enumerate(ring_w):
            if f == nz:  # no object: the sensor's bottom is the probe's outer surface
                fi, fw, gi, gw = bottom_flux(i)
                qs_i += fi
                qs_w += [wz * wa * w for w in fw]
                qs_gi += gi
                qs_gw += [wz * wa * w for w in gw]
                continue
            g = grid.g_z_W_K[f - 1, i] / area[i]
            qs_i += [flat(f - 1, i), flat(f, i)]
            qs_w += [wz * wa * g, -wz * wa * g]

    qf_i, qf_w, qf_gi, qf_gw = [], [], [], []
    for i, wa in enumerate(ring_w):
        fi, fw, gi, gw = bottom_flux(i)
        qf_i += fi
        qf_w += [wa * w for w in fw]
        qf_gi += gi
        qf_gw += [wa * w for w in gw]

    idx, w = [], []
    for a, b, c, d in ((tc_i, tc_w, tc_gi, tc_gw), (qs_i, qs_w, qs_gi, qs_gw), (qf_i, qf_w, qf_gi, qf_gw)):
        idx += [np.asarray(a, dtype=int), np.asarray(c, dtype=int)]
        w += [np.asarray(b, dtype=float), np.asarray(d, dtype=float)]
    return Probes(idx=tuple(idx), w=tuple(w))


@dataclass
class Record:
    """Outputs at ``t_s`` (``t_s[0] = 0``, the initial state), plus the energy ledger.

    ``E_in_J``: source energy delivered by each time; ``E_stored_J``: change of
    the stored heat ``sum C (T - T_initial)``; ``E_lost_J``: heat that left
    through the outer surfaces (integrated with the scheme's own quadrature,
    so ``E_in = E_stored + E_lost`` holds to round-off for any step).
    """

    t_s: np.ndarray
    T_tc_K: np.ndarray
    q_sensor_W_m2: np.ndarray
    q_face_W_m2: np.ndarray
    E_in_J: np.ndarray
    E_stored_J: np.ndarray
    E_lost_J: np.ndarray
    T_final_K: np.ndarray | None = None


# ----------------------------------------------------------------------------------------------
# The solver


class Solver:
    """Time stepper for one grid and one step ``dt_s`` (factorised once).

    Parameters
    ----------
    grid : Grid
        A grid from :func:`~firmware_sim.rz.grid.probe_grid` (outputs need its
        ``meta``) or any :class:`Grid` when only fields are wanted.
    dt_s : float
        Time step.
    scheme : {"trbdf2", "cn", "be"}
        Time integrator (see the module docstring).
    rannacher_steps : int
        For ``"cn"``: backward-Euler half steps at the start (and after a
        :meth:`run` begins from a new state), 0 for plain CN.
    probes : Probes, optional
        The grid's read-out weights when already built (another solver of the same grid
        has them: they depend on the grid only).
    factor_now : bool
        Factor here (default); False defers it to the first solve (:attr:`fac`), which a world
        whose steps are all recalled (:mod:`firmware_sim.rz.stepmemo`) never makes.
    """

    def __init__(self, grid: Grid, dt_s: float, scheme: str = "trbdf2", rannacher_steps: int = 2,
                 probes: Probes | None = None, *, factor_now: bool = True) -> None:
        if scheme not in SCHEMES:
            raise ValueError(f"scheme must be one of {SCHEMES}, got {scheme!r}")
        if not (dt_s > 0 and math.isfinite(dt_s)):
            raise ValueError("dt_s must be finite and > 0")
        self.grid, self.dt, self.scheme = grid, float(dt_s), scheme
        self.rannacher_steps = int(rannacher_steps)
        self.op = _Operator(grid)
        # One matrix C/tau + K per scheme: BE tau = dt; CN tau = dt/2 (also the BE half step);
        # TR-BDF2 tau = gamma dt / 2 = w dt for both stages.
        self.tau = {"be": dt_s, "cn": 0.5 * dt_s, "trbdf2": 0.5 * _GAMMA * dt_s}[scheme]
        self._fac: BlockTridiagonal | None = None
        if factor_now:
            self._fac = self.op.factor(1.0 / self.tau)
        self._Ct = self.op.cap / self.tau
        self.g_t = grid.g_b_W_K * grid.t_b_K   # ambient forcing vector g
        self.g_t.flags.writeable = False        # swapped (step_response), never edited: its digest is kept
        # (array, digest) pairs, each replaced whole (worlds may step in other threads): what a step
        # reads for this forcing array, and the last read-only source pattern (_step_key).
        self._key_base: tuple = (None, b"")
        self._src_key: tuple = (None, b"", 0.0)    # (array, digest, float(np.sum(array)))
        if probes is None and grid.meta.get("sensor_radius_m") is not None:
            probes = _probes(grid)
        self.probes = probes
        self._rest_key, self._rest = None, None
        self._g_sum_of, self._g_sum = None, 0.0     # sum of the forcing, per forcing array (_loss)
        self._first_active = int(np.flatnonzero(grid.active)[0])

    @property
    def fac(self) -> BlockTridiagonal:
        """The factor of ``C / tau + K`` (built, or taken from the shared cache, at its first use if deferred)."""
        fac = self._fac
        if fac is None:
            fac = self._fac = self.op.factor(1.0 / self.tau)
        return fac

    # -- rest
    def _rest_range(self) -> tuple[float, float] | None:
        """Temperatures a uniform, unheated field can have and be at rest; None if there are none.

        With every outer surface at one temperature ``T_u`` (or none losing heat), the uniform
        field ``T_u`` is the conductance matrix's steady state (rows of ``K`` sum to the surface
        conductance), so with no source a step from it returns it.  A probe in air waiting for its
        touch, or resting on an object at its temperature, can spend much of a simulated session
        there, and the solve would only add round-off.  The surfaces' temperatures come out of
        the forcing to a few ulps, so ``T_u`` may differ from each by 1e-12 of itself.  Checked,
        not assumed: one step of the scheme from such a field must return it to round-off, or
        there is no rest.  Keyed on the forcing array (a step response swaps in a zero forcing).
        """
        if self._rest_key is self.g_t:
            return self._rest
        self._rest_key, self._rest = self.g_t, None
        gb = self.grid.g_b_W_K
        on = gb > 0
        if np.any(on):
            T_s = self.g_t[on] / gb[on]
            lo, hi = float(T_s.min()), float(T_s.max())
            tol = 1e-12 * max(1.0, abs(lo), abs(hi))
            if not hi - lo <= tol:
                return None
            rng, T_ref = (hi - tol, lo + tol), 0.5 * (lo + hi)
        else:
            rng, T_ref = (-math.inf, math.inf), 1.0     # adiabatic: any uniform field is at rest
        field = T_ref * self.grid.active
        T, _, _ = self._advance(field, self.g_t, self._loss(field), False, False)
        if np.max(np.abs(T - field)) <= 1e-12 * max(1.0, abs(T_ref)):
            self._rest = rng
        return self._rest

    def _at_rest(self, T: np.ndarray, amplitude: float) -> bool:
        """``T`` is uniform over the active cells at a rest temperature, and nothing heats."""
        if amplitude != 0.0:
            return False
        # The field's uniformity first: it costs a comparison, where the rest range costs a step of
        # the scheme (and the factor, if no solve needed it yet), and most unheated fields (a
        # touch's contact transient, a probe cooling after a lift) are not uniform.
        T_u = float(T.flat[self._first_active])
        if not np.array_equal(T, T_u * self.grid.active):
            return False
        rng = self._rest_range()
        return rng is not None and rng[0] <= T_u <= rng[1]

    # -- fields
    def initial_field(self, T_probe_K: float, T_object_K: float | None = None) -> np.ndarray:
        """Uniform probe (every layer but ``object``) at ``T_probe_K``, object at ``T_object_K``."""
        g = self.grid
        T = np.full(g.shape, float(T_probe_K))
        if T_object_K is not None and "object" in [l.name for l in g.layers]:
            T[g.rows_of("object")] = float(T_object_K)
        return T * g.active

    def _loss(self, T: np.ndarray) -> float:
        """Heat flow (W) out through the outer surfaces, ``sum g (T - T_inf)``."""
        g = self.g_t
        if self._g_sum_of is not g:     # (a step response swaps in a zero forcing)
            self._g_sum_of, self._g_sum = g, np.sum(g)
        return float(np.sum(self.op.gb * T) - self._g_sum)

    def _read(self, T: np.ndarray) -> np.ndarray:
        return self.probes.read(T, self.g_t) if self.probes is not None else np.zeros(3)

    def run(self, T0_K: np.ndarray, n_steps: int, source_W: np.ndarray | None = None,
            amplitude: np.ndarray | float = 0.0, keep_field: bool = False) -> Record:
        """March ``n_steps`` steps from field ``T0_K``.

        Parameters
        ----------
        T0_K : ndarray, grid shape
            Initial temperatures.
        n_steps : int
            Number of steps of ``dt_s``.
        source_W : ndarray, grid shape, optional
            Per-cell source pattern (W per unit amplitude), e.g.
            :meth:`Grid.volume_source_W` for the heater.
        amplitude : float or ndarray (n_steps,)
            Source amplitude on each step (constant within the step).
        keep_field : bool
            Return the final field in ``Record.T_final_K``.
        """
        C = self.op.cap
        Q = np.zeros(self.grid.shape) if source_W is None else np.asarray(source_W, float)
        p = np.broadcast_to(np.asarray(amplitude, float), (n_steps,))
        g = self.g_t
        T = np.array(T0_K, dtype=float) * self.grid.active
        E0 = float(np.sum(C * T))
        Q_tot = float(np.sum(Q))
        out = np.empty((n_steps + 1, 3))
        E_in = np.zeros(n_steps + 1)
        E_st = np.zeros(n_steps + 1)
        E_lo = np.zeros(n_steps + 1)
        out[0] = self._read(T)
        loss = self._loss(T)
        dt = self.dt
        for n in range(n_steps):
            T, loss, lost = self._advance(T, p[n] * Q + g, loss, n < self.rannacher_steps, self._at_rest(T, p[n]))
            out[n + 1] = self._read(T)
            E_in[n + 1] = E_in[n] + dt * p[n] * Q_tot
            E_lo[n + 1] = E_lo[n] + lost
            E_st[n + 1] = float(np.sum(C * T)) - E0
        t = dt * np.arange(n_steps + 1)
        return Record(t_s=t, T_tc_K=out[:, 0], q_sensor_W_m2=out[:, 1], q_face_W_m2=out[:, 2],
                      E_in_J=E_in, E_stored_J=E_st, E_lost_J=E_lo, T_final_K=T if keep_field else None)

    def _advance(self, T: np.ndarray, f: np.ndarray, loss: float, startup: bool,
                 rest: bool) -> tuple[np.ndarray, float, float]:
        """One step of the scheme from ``T`` with forcing ``f`` (source + ambient, constant in the step).

        ``loss`` is the outward heat flow of ``T`` (W); ``startup``: a Rannacher half-step pair
        (``"cn"`` only); ``rest``: ``T`` is at rest (:meth:`_at_rest`), and the step returns it
        without solving.  Returns the new field, its outward heat flow and the heat lost
        in the step (J, the scheme's own quadrature, so the energy ledger closes to round-off).
        """
        if rest:
            # Every scheme's quadrature of a constant outward flow over the step is dt times it.
            return T.copy(), loss, self.dt * loss
        op, fac, dt, Ct = self.op, self.fac, self.dt, self._Ct
        if self.scheme == "be":
            T = op.solve(fac, Ct * T + f)
            loss_new = self._loss(T)
            lost = dt * loss_new
        elif self.scheme == "cn" and startup:
            # Two backward-Euler half steps: (2C/dt + K) is the CN matrix.
            T_h = op.solve(fac, Ct * T + f)
            l_h = self._loss(T_h)
            T = op.solve(fac, Ct * T_h + f)
            loss_new = self._loss(T)
            lost = 0.5 * dt * (l_h + loss_new)
        elif self.scheme == "cn":
            T = op.solve(fac, Ct * T - op.apply_K(T) + 2.0 * f)
            loss_new = self._loss(T)
            lost = 0.5 * dt * (loss + loss_new)
        else:  # TR-BDF2
            # TR stage to t + gamma dt: (C/tau + K) T_g = (C/tau - K) T + 2 f.
            # (In place, the operations and their order as written: (Ct T - K T) + 2 f.)
            rhs = Ct * T
            rhs -= op.apply_K(T)
            rhs += 2.0 * f
            T_g = op.solve(fac, rhs)
            l_g = self._loss(T_g)
            # BDF2 stage: (C/tau + K) T1 = C/tau [T_g / (g (2-g)) - (1-g)^2 / (g (2-g)) T] + f.
            rhs = _BDF2_A * T_g
            rhs -= _BDF2_C * T
            rhs *= Ct
            rhs += f
            T = op.solve(fac, rhs)
            loss_new = self._loss(T)
            lost = dt * ((loss + l_g) / (2.0 * (2.0 - _GAMMA)) + _W * loss_new)
        return T, loss_new, lost

    def step(self, T_K: np.ndarray, source_W: np.ndarray, amplitude: float) -> tuple[np.ndarray, float, float]:
        """One step from field ``T_K``: ``(new field, heat in J, heat lost J)``.

        The same arithmetic as one step of :meth:`run` (and the same numbers, bit for bit),
        without its per-call records: a world that steps once per call pays for the step only.
        For ``"cn"`` the step is a plain CN step (no Rannacher start).  A step this process has
        taken before from the same field with the same inputs is recalled, not solved
        (:mod:`firmware_sim.rz.stepmemo`: the stored result of the same arithmetic, so the same bits).
        """
        T = np.asarray(T_K, dtype=float) * self.grid.active    # (a new array: the product)
        key = self._step_key(T, source_W, float(amplitude))
        hit = recall(key)
        if hit is not None:
            return hit
        T1, _, lost = self._advance(T, amplitude * source_W + self.g_t, self._loss(T), False,
                                    self._at_rest(T, amplitude))
        of, _, src_sum = self._src_key
        e_in = self.dt * amplitude * (src_sum if source_W is of else float(np.sum(source_W)))
        keep(key, T1, e_in, lost)
        return T1, e_in, lost

    def _step_key(self, T: np.ndarray, source_W: np.ndarray, amplitude: float) -> bytes:
        """SHA-256 of everything :meth:`step` reads: the solver's arrays and step, forcing, source, amplitude, field.

        The grid's arrays are digested at the first step (a grid is not edited once its solver is
        built: the factor would not follow either); the forcing whenever the solver's forcing array
        is another one, or every step if it is writeable; the source pattern likewise (a world's is
        read-only, :class:`firmware_sim.rz.configs.GridConfig`).
        """
        g = self.g_t
        of, base = self._key_base
        if of is not g or g.flags.writeable:
            h = hashlib.sha256()
            op = self.op
            h.update(f"{self.scheme} {self.dt!r} {self.tau!r} {self.grid.shape}".encode())
            for a in (op.cap, op.k_diag, op.gr, op.gz, op.gb, self.grid.active, g):
                a = np.ascontiguousarray(a)
                h.update(f"{a.dtype.str}{a.shape}".encode())
                h.update(a.data)
            base = h.digest()
            self._key_base = (g, base)
        of, src_key, _ = self._src_key
        if source_W is not of:
            src = np.ascontiguousarray(source_W, dtype=float)
            src_key = hashlib.sha256(repr(src.shape).encode() + src.tobytes()).digest()
            if isinstance(source_W, np.ndarray) and not source_W.flags.writeable and source_W.base is None:
                # Its sum too (the step's heat in): read-only, so the same bits each step.
                self._src_key = (source_W, src_key, float(np.sum(source_W)))
        h = hashlib.sha256(base)
        h.update(src_key)
        h.update(struct.pack("<d", amplitude))
        h.update(np.ascontiguousarray(T).data)   # row-major bytes: a field's values, whatever its layout
        return h.digest()

    # -- linear building blocks
    def heater_source_W(self, power_W: float = 1.0) -> np.ndarray:
        """Per-cell power of ``power_W`` released uniformly in the heater disk (grid's heater radius)."""
        meta = self.grid.meta
        q_v = power_W / meta["heater_volume_m3"]
        return self.grid.volume_source_W("heater", meta["heater_radius_m"], q_v)

    def step_response(self, n_steps: int, *, per: str = "W") -> Record:
        """Response to a unit heater step from t = 0 with zero initial and ambient temperatures.

        ``per="W"``: per watt of heater power; ``per="q_v"``: per W/m^3 in the heater disk.
        """
        saved = self.g_t
        self.g_t = np.zeros_like(saved)  # the step response carries no ambient forcing
        try:
            src = self.heater_source_W(1.0)
            if per == "q_v":
                src = src * self.grid.meta["heater_volume_m3"]
            elif per != "W":
                raise ValueError("per must be 'W' or 'q_v'")
            return self.run(np.zeros(self.grid.shape), n_steps, src, 1.0)
        finally:
            self.g_t = saved

    def free_response(self, n_steps: int, T_probe_K: float, T_object_K: float | None = None) -> Record:
        """Unheated response from a uniform probe and object (the contact transient), ambient as built."""
        return self.run(self.initial_field(T_probe_K, T_object_K), n_steps)

    @staticmethod
    def superpose(free: Record, step: Record, power_W: np.ndarray) -> dict[str, np.ndarray]:
        """Outputs for heater power ``power_W[n]`` on step n: free + sum of delayed unit steps.

        Exact for the discrete scheme (linear, time-invariant, power constant
        within a step), so it equals a direct :meth:`run` to round-off.
        """
        p = np.asarray(power_W, float)
        n = p.size
        dp = np.diff(np.r_[0.0, p])
        out = {}
        for name in ("T_tc_K", "q_sensor_W_m2", "q_face_W_m2"):
            s = getattr(step, name)[: n + 1]
            # y[m] = free[m] + sum_k dp[k] s[m - k]: a causal convolution (s[0] = 0, a step
            # switched on at t_k has not yet moved anything at t_k).
            out[name] = getattr(free, name)[: n + 1] + np.convolve(dp, s)[: n + 1]
        return out


def steady_state(grid: Grid, source_W: np.ndarray) -> np.ndarray:
    """Steady field ``K T = Q + g`` (needs at least one surface with h > 0)."""
    op = _Operator(grid)
    if not np.any(grid.g_b_W_K > 0):
        raise ValueError("no steady state: every surface is adiabatic")
    fac = op.factor(0.0)
    return op.solve(fac, np.asarray(source_W, float) + grid.g_b_W_K * grid.t_b_K) * grid.active
