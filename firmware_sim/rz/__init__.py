"""An independent thermal model of the probe: axisymmetric (r, z) finite volumes, NumPy only.

The simulator's present world (:mod:`firmware_sim.world`) is the exact 1-D
Laplace solution -- the idealisation the device's estimator inverts.  This
package is the independent one: the probe's real geometry (PU-foam substrate,
heater film of finite area, sensing layer, a 10 x 10 mm flux sensor inside it)
on a finite object, with contact resistance, lateral heat spreading and
surface losses, solved on a graded grid with an unconditionally stable
implicit stepper.  It shares no model code with the estimator (only the
material data and probe constants).

* :mod:`firmware_sim.rz.grid` -- layers, boundaries, graded grid, probe factory;
* :mod:`firmware_sim.rz.solver` -- banded block solver, BE / CN / TR-BDF2
  stepping, thermocouple and flux-sensor read-outs, energy ledger, unit-step
  responses and their superposition.
* :mod:`firmware_sim.rz.stepmemo` -- steps already taken in this process, recalled bit for bit;
* :mod:`firmware_sim.rz.footprint` -- the thermopile's real square (offset,
  sensitivity map) as exact radial weights of the read-out.

Verification: ``tests/test_rz_world.py``; speed: ``bench/rz_world_bench.py``.
"""

from firmware_sim.rz.grid import (AIR, PU_FOAM, Boundary, Grid, Layer, Mesh, graded_faces, half_space_grid,
                                  heater_disk_radius_m, probe_grid)
from firmware_sim.rz.solver import Record, Solver, axis_value, steady_state

__all__ = ["AIR", "PU_FOAM", "Boundary", "Grid", "Layer", "Mesh", "graded_faces", "half_space_grid",
           "heater_disk_radius_m", "probe_grid", "Record", "Solver", "axis_value", "steady_state"]
