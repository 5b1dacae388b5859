"""Regenerate ``data/axisym_rz_reference.npz``: the (r, z) finite-volume reference for test_axisym.

The independent world model (firmware_sim/rz) on the small-heater probe for
glass, PMMA and aluminium (large object, 0.1 m x 0.1 m, standing for a
half-space over 5 s), unit-step responses per watt on two grids: the default
mesh with dt = 20 ms and the mesh refined by 2 with dt = 10 ms.  Both the
space and the time discretisation are second order (observed orders in
tests/firmware_sim/rz), so the Richardson value ``f2 + (f2 - f1) / 3`` is
stored with both runs.  Takes ~1.5 min; the test itself re-runs the coarse
case live for one material to check the stored data still is what the
model gives.

Run:  PYTHONPATH=. python tests/edge/physics/make_axisym_reference.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from edge.physics.geometry import PROBES
from edge.physics.solids import Solid
from firmware_sim.rz.grid import Mesh, probe_grid
from firmware_sim.rz.solver import Solver

SOLIDS = {"glass": Solid(1.097, 2458.4, 809.0), "pmma": Solid(0.185, 1178.35, 1429.0),
          "aluminium": Solid(237.0, 2702.0, 903.0)}
OBJECT_SIZE_m = 0.1
T_END_s = 5.0
OUT = Path(__file__).resolve().parent / "data" / "axisym_rz_reference.npz"


def rz_step(solid: Solid, dt_s: float, refine: int, probe: str = "small-heater", t_end_s: float = T_END_s):
    """(t_s, T_tc_K, q_sensor_W_m2) per watt from 0 to ``t_end_s`` on the rz grid ``refine``."""
    g = PROBES[probe]
    grid = probe_grid(solid, object_thickness_m=OBJECT_SIZE_m, object_radius_m=OBJECT_SIZE_m,
                      heater_radius_m=g.heater_radius_m, probe_radius_m=g.probe_radius_m,
                      sensor_radius_m=g.sensor_radius_m, mesh=Mesh(refine=refine))
    rec = Solver(grid, dt_s).step_response(int(round(t_end_s / dt_s)))
    return rec.t_s, rec.T_tc_K, rec.q_sensor_W_m2


def main() -> None:
    out = {}
    for name, s in SOLIDS.items():
        t, T1, q1 = rz_step(s, 0.02, 1)
        _, T2, q2 = rz_step(s, 0.01, 2)
        T2, q2 = T2[::2], q2[::2]
        out["t_s"] = t
        for key, a, b in (("T", T1, T2), ("q", q1, q2)):
            out[f"{name}_{key}_coarse"] = a
            out[f"{name}_{key}_fine"] = b
            out[f"{name}_{key}_richardson"] = b + (b - a) / 3.0
        out[f"{name}_solid"] = np.array([s.k_W_mK, s.rho_kg_m3, s.c_J_kgK])
    OUT.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(OUT, **out)
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
