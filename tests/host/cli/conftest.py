"""The CLI is tested through ``host.cli.main.main(argv)`` as a user types it."""

import pytest

from edge.physics.forward import simulate
from edge.physics.solids import Solid
from host.records import write_record

#: A two-object set as a user writes it (k, rho, c; e computed).
KITCHEN = "name,class,k_W_mK,rho_kg_m3,c_J_kgK\nwindow,glass,1.1,2450,810\nlid,polymer,0.19,1180,1430\n"

#: Tempered glass, paper Table 2.
GLASS = Solid(1.097, 2458.4, 809.0)


@pytest.fixture
def glass_record(tmp_path):
    """A 2-s exact-model record on glass at 7.7e7 W/m^3, written as a record CSV."""
    r = simulate(GLASS, 7.7e7, 2.0, back="infinite", scheme="exact", dt_s=0.01)
    p = tmp_path / "glass.csv"
    write_record(p, r.t_s, r.T_f_K, r.q_f_W_m2)
    return p


@pytest.fixture
def kitchen(tmp_path):
    """:data:`KITCHEN` written to ``kitchen.csv``."""
    p = tmp_path / "kitchen.csv"
    p.write_text(KITCHEN)
    return p
