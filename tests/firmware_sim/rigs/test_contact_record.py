"""The contact-record rig's boards: its converter steps are the chip registry's, and a record is quantised to them."""

import numpy as np
import pytest

from edge.hw.chips import BOARDS as CHIP_BOARDS, CHIPS, FLUX, THERMOCOUPLE
from firmware_sim.rigs.contact_record import BOARDS


def test_the_reference_boards_steps_are_the_registrys_instrument_models():
    chips = CHIP_BOARDS["reference"]
    lsb_T, lsb_q = BOARDS["reference"][2]
    assert lsb_T == CHIPS[chips[THERMOCOUPLE]].models[THERMOCOUPLE].lsb
    assert lsb_q == CHIPS[chips[FLUX]].models[FLUX].lsb
    # The MCP9600 at 16 bit (the rig's 80-ms period) resolves 8 uV of type K EMF, about 0.2 K: not its 0.0625 K register.
    assert lsb_T == pytest.approx(0.197, abs=0.001) and BOARDS["reference"][0] == pytest.approx(0.08)


def test_a_reference_board_record_sits_on_the_thermometers_steps():
    from edge.physics.solids import Solid
    from firmware_sim.rigs.contact_record import ContactTouch, record_touch

    rec = record_touch(ContactTouch(Solid(0.2, 1190.0, 1470.0), lead_s=0.2, heat_s=0.3, pre_s=0.2),
                       board="reference", world_dt_s=0.08, seed=3)
    lsb_T, lsb_q = BOARDS["reference"][2]
    for x, lsb in ((rec["T_C"], lsb_T), (rec["q_W_m2"], lsb_q)):
        k = x / lsb
        np.testing.assert_allclose(k, np.round(k), atol=1e-6)
