"""The probe's forward model: heater power in, surface temperature and flux out.

Implements the 1-D transient model of Ma & Zhang (2024), section 2.2,
eqs. (1)-(6): an insulated top, a heater layer releasing q_v, a sensing layer,
and the object.  Outputs are the excess temperature T_f(t) at the object
surface and the heat flux q_f(t) into the object.

Schemes
-------
``"paper"``
    The paper's explicit scheme as written: uniform grid (40 um by default)
    through probe and object, the paper's interface node (object half cell
    only), forward Euler with the step chosen automatically from each cell's
    stability limit.  Reference for what the paper computed; first order.
``"explicit"``
    The same explicit march on the same uniform grid but with consistent
    interface control volumes - isolates the cost of the interface error.
``"default"``
    Consistent control volumes on a grid sized to the scene (uniform in the
    probe, graded in the object to the penetration depth), integrated exactly
    in time by modal decomposition.  Second order in space, no time error,
    unconditionally stable.
``"exact"``
    Laplace-domain quadrupole solution inverted by fixed Talbot (no grid).

The model is linear in q_v: :func:`step_response` is computed once per
material and :func:`scale_levels` turns it into any number of power levels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from edge.physics import fvm, laplace
from edge.checks import (
    finite_array,
    finite_nonnegative,
    finite_positive,
    one_of,
    strictly_increasing,
)
from edge.physics.integrators import ModalSolver, explicit_march
from edge.physics.schedule import PowerSchedule
from edge.physics.probe import DEFAULT_STACK, ProbeStack
from edge.physics.solids import Solid

SCHEMES = ("paper", "explicit", "default", "exact")
PAPER_DX_m = 40e-6
PAPER_THICKNESS_m = 0.04


@dataclass(frozen=True)
class ProbeResponse:
    """Result of a forward simulation (per unit area where it applies).

    Attributes
    ----------
    t_s : output times (s).
    T_f_K : excess object-surface temperature at ``t_s`` (K).
    q_f_W_m2 : heat flux into the object at ``t_s`` (W/m^2).
    scheme : scheme used.
    energy_J_m2 : released, stored and conducted-out heat at the last time
        (empty for the exact scheme).
    n_nodes, n_steps : grid size and number of time steps (0 for ``exact``).
    domain_m : modelled object depth (m).
    """

    t_s: np.ndarray
    T_f_K: np.ndarray
    q_f_W_m2: np.ndarray
    scheme: str
    energy_J_m2: dict = field(default_factory=dict)
    n_nodes: int = 0
    n_steps: int = 0
    domain_m: float = math.inf

    @property
    def energy_residual(self) -> float:
        """(released - stored - out) / released; 0 when nothing was released."""
        e = self.energy_J_m2
        if not e or e["released"] == 0.0:
            return 0.0
        return (e["released"] - e["stored"] - e["conducted_out"]) / e["released"]


def output_times(duration_s: float, dt_s: float | None = None, t_s=None) -> np.ndarray:
    """Validated output times: explicit ``t_s`` or a grid 0, dt, ..., duration (s)."""
    duration_s = finite_positive("duration_s", duration_s)
    if t_s is not None:
        t = finite_array("t_s", t_s)
        strictly_increasing("t_s", t)
        if t[0] < 0 or t[-1] > duration_s * (1 + 1e-12):
            raise ValueError("t_s must lie within [0, duration_s]")
        return t
    dt = finite_positive("dt_s", dt_s if dt_s is not None else min(0.01, duration_s / 10))
    n = max(1, int(round(duration_s / dt)))
    return np.linspace(0.0, duration_s, n + 1)


def _check_scene(solid, thickness_m, back):
    if not isinstance(solid, Solid):
        raise ValueError(f"solid must be a Solid, got {type(solid).__name__}")
    one_of("back", back, fvm.BACKS)
    if back != "infinite":
        if thickness_m is None:
            raise ValueError(f"thickness_m is required for back={back!r}")
        thickness_m = finite_positive("thickness_m", thickness_m)
    return thickness_m if back != "infinite" else None


def build_grid(
    solid: Solid,
    *,
    scheme: str,
    duration_s: float,
    t_first_s: float,
    thickness_m: float | None,
    back: str,
    stack: ProbeStack,
    dx_m: float = PAPER_DX_m,
    n_probe: int = 32,
    growth: float = 1.06,
    depth_factor: float = 5.0,
) -> fvm.Grid:
    """The grid a scheme uses for this scene (see module docstring)."""
    if scheme in ("paper", "explicit"):
        # The paper models 40 mm; an infinite object gets what heat reaches.
        if back == "infinite":
            depth = max(PAPER_THICKNESS_m, 6.0 * math.sqrt(solid.alpha_m2_s * duration_s))
            end = "fixed"
        else:
            depth, end = thickness_m, back
        return fvm.uniform_grid(
            stack, solid, dx_m=dx_m, depth_m=depth, back=end,
            interface="paper" if scheme == "paper" else "consistent",
        )
    return fvm.graded_grid(
        stack, solid, duration_s=duration_s, t_first_s=t_first_s, thickness_m=thickness_m,
        back=back, n_probe=n_probe, growth=growth, depth_factor=depth_factor,
    )


def simulate(
    solid: Solid,
    q_v,
    duration_s: float,
    *,
    q_v_times_s=None,
    t_s=None,
    dt_s: float | None = None,
    thickness_m: float | None = PAPER_THICKNESS_m,
    back: str = "fixed",
    scheme: str = "default",
    stack: ProbeStack = DEFAULT_STACK,
    contact_resistance_m2K_W: float = 0.0,
    dx_m: float = PAPER_DX_m,
    n_probe: int = 32,
    growth: float = 1.06,
    depth_factor: float = 5.0,
    max_steps: int = 3_000_000,
) -> ProbeResponse:
    """Simulate a touch: T_f(t) and q_f(t) for heater power density q_v(t).

    Parameters
    ----------
    solid : Solid
        The object's k, rho, c.
    q_v : float or array or PowerSchedule
        Heater power density (W/m^3): a constant, or a piecewise-constant
        series whose switching times are ``q_v_times_s`` (s, starting at 0).
    duration_s : float
        Length of the record (s).
    t_s, dt_s : output times (s), or their spacing (default 0.01 s).
    thickness_m, back : object thickness (m) and back boundary: ``"fixed"``
        (held at T0, the paper's 40 mm), ``"insulated"`` or ``"infinite"``.
    scheme : ``"paper"``, ``"explicit"``, ``"default"`` or ``"exact"``.
    stack : ProbeStack
        Probe layer geometry (see :mod:`edge.physics.solids`).
    contact_resistance_m2K_W : float
        Probe-object contact resistance; only the ``"exact"`` scheme models it.
    dx_m : grid spacing of the paper/explicit schemes (m).
    n_probe, growth, depth_factor : resolution of the default scheme.
    max_steps : refuse explicit runs needing more steps than this.

    Returns
    -------
    ProbeResponse
    """
    one_of("scheme", scheme, SCHEMES)
    thickness_m = _check_scene(solid, thickness_m, back)
    schedule = PowerSchedule.coerce(q_v, q_v_times_s)
    t = output_times(duration_s, dt_s, t_s)
    rc = finite_nonnegative("contact_resistance_m2K_W", contact_resistance_m2K_W)
    if rc > 0 and scheme != "exact":
        raise ValueError("contact_resistance_m2K_W is only modelled by scheme='exact'")
    if scheme == "exact":
        T, q = superpose(schedule, t, lambda tt: laplace.probe_step_response(
            solid, tt, stack=stack, thickness_m=thickness_m, back=back, contact_resistance_m2K_W=rc))
        return ProbeResponse(t, T, q, scheme)
    t_first = float(t[t > 0][0]) if np.any(t > 0) else float(duration_s)
    grid = build_grid(
        solid, scheme=scheme, duration_s=float(t[-1]) if t[-1] > 0 else duration_s, t_first_s=t_first,
        thickness_m=thickness_m, back=back, stack=stack, dx_m=dx_m, n_probe=n_probe, growth=growth,
        depth_factor=depth_factor,
    )
    rows = np.vstack(grid.interface_rows())
    if scheme == "default":
        res = ModalSolver(grid).march(schedule, t, rows)
    else:
        res = explicit_march(grid, schedule, t, rows, max_steps=max_steps)
    energy = {"released": res.released_J_m2, "stored": res.stored_J_m2, "conducted_out": res.conducted_out_J_m2}
    return ProbeResponse(
        t, res.outputs[0], res.outputs[1], scheme, energy, grid.n, res.n_steps, grid.domain_m
    )


def superpose(schedule: PowerSchedule, t: np.ndarray, step) -> tuple[np.ndarray, np.ndarray]:
    """Combine unit-step responses ``step(times) -> (T, q)`` for a schedule (linearity)."""
    dq = np.diff(np.concatenate(([0.0], schedule.q_v_W_m3)))
    T = np.zeros(t.size)
    q = np.zeros(t.size)
    for t0, d in zip(schedule.t_start_s, dq):
        if d == 0.0:
            continue
        m = t > t0
        if m.any():
            Ts, qs = step(t[m] - t0)
            T[m] += d * Ts
            q[m] += d * qs
    return T, q


def step_response(solid: Solid, duration_s: float, **kwargs) -> ProbeResponse:
    """Response to q_v = 1 W/m^3 from t = 0: scale it to any constant power."""
    return simulate(solid, 1.0, duration_s, **kwargs)


def scale_levels(unit: ProbeResponse, q_v_levels_W_m3) -> tuple[np.ndarray, np.ndarray]:
    """T_f and q_f, shape (n_levels, n_t), for constant power levels from a unit response."""
    q = finite_array("q_v_levels_W_m3", q_v_levels_W_m3)
    if np.any(q < 0):
        raise ValueError("q_v_levels_W_m3 must be >= 0")
    return np.outer(q, unit.T_f_K), np.outer(q, unit.q_f_W_m2)
