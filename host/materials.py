"""The material library, re-exported for host code (it lives in :mod:`edge.physics.materials`).

The library is pure NumPy and standard library, so the simulator and the
device can read it too; host modules keep importing it from here.
"""

from edge.physics.materials import *  # noqa: F401,F403
from edge.physics.materials import __all__  # noqa: F401
