"""``objects add`` names the pairs the probe cannot separate at the user's contact time (ISSUE #37 item 5)."""

import math

import pytest

from edge.hw.chips import BOARDS, CHIPS, FLUX, THERMOCOUPLE
from edge.recognition import KnownObject, ObjectSet
from host.cli.objects import separation_warnings
from host.objects import attainable_u_ln_e, board_noise, inseparable_pairs

P = KnownObject.from_properties
SET = ObjectSet((P("foam", "foam", 0.035, 30, 1400, 0.05), P("oak", "wood", 0.18, 700, 1600, 0.05),
                 P("abs", "polymer", 0.17, 1050, 1400, 0.05), P("al", "alloy", 160.0, 2800, 880, 0.05),
                 P("copper", "metal", 380.0, 8900, 380, 0.05)))


def test_attainable_u_shrinks_with_contact_time_and_grows_with_e():
    u1, u2 = attainable_u_ln_e(SET, 1.0), attainable_u_ln_e(SET, 2.0)
    assert all(u2[n] < u1[n] for n in SET.names)
    assert u1["copper"] > u1["oak"]


def test_one_warning_per_inseparable_pair_at_the_users_contact_time():
    short = separation_warnings(SET, 0.5)
    long = separation_warnings(SET, 2.0)
    # oak (e 449) and ABS (e 499) lie 10 % apart: with 5 % spreads no contact time separates them.
    assert any("abs and oak" in w or "oak and abs" in w for w in long)
    # aluminium and copper (ln e 0.59 apart) are separable at 2 s but not at 0.5 s, where a metal's u(e) is large.
    assert not any("al and copper" in w for w in long)
    assert any("al and copper" in w for w in short)
    assert all(w.startswith("warning: ") and "\n" not in w for w in short)
    pairs = inseparable_pairs(SET, attainable_u_ln_e(SET, 0.5))
    assert len(short) == len(pairs) and all(p["delta_ln_e"] < p["threshold_ln"] for p in pairs)


def test_a_catalogue_is_not_checked_pair_by_pair():
    from host.cli.objects import MAX_SEPARATION_OBJECTS
    big = ObjectSet([P(f"o{i}", "glass", 1.0, 2500, 800, 0.05) for i in range(MAX_SEPARATION_OBJECTS + 1)])
    (line,) = separation_warnings(big, 1.0)
    assert "not checked" in line


def test_the_bound_takes_the_boards_noise_from_the_chip_registry():
    for board, roles in BOARDS.items():
        sT, sq, dt = board_noise(board)
        T, q = CHIPS[roles[THERMOCOUPLE]].models[THERMOCOUPLE], CHIPS[roles[FLUX]].models[FLUX]
        assert sT == pytest.approx(math.hypot(T.noise, T.lsb / math.sqrt(12.0)))
        assert sq == pytest.approx(math.hypot(q.noise, q.lsb / math.sqrt(12.0)))
        assert dt == pytest.approx(1.0 / min(50.0, T.rate_Hz))   # the MCP9600 converts at 12.5 Hz
    with pytest.raises(ValueError, match="unknown board"):
        board_noise("breadboard")
    # A noisier, slower board resolves less: the reference board's bound is wider on every object.
    precise, coarse = attainable_u_ln_e(SET, 1.0), attainable_u_ln_e(SET, 1.0, board="reference")
    assert all(coarse[n] > precise[n] for n in SET.names)
    # Given noise overrides the board's.
    quiet = attainable_u_ln_e(SET, 1.0, sigma_T_K=1e-4, sigma_q_W_m2=1e-2)
    assert all(quiet[n] < precise[n] for n in SET.names)
