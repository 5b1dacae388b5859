"""host.calibration.checked_calibration: the written calibration's own answers hold its references within u."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from edge.calibration.model import ProbeCalibration
from edge.calibration.selfcheck import REFERENCE_Z
from host.calibration import checked_calibration

NAMES = ["pmma", "pmma", "pyroceram", "pyroceram", "aisi_304", "aisi_304"]
E_REFS = [558.0, 558.0, 2892.0, 2892.0, 7493.0, 7493.0]
U_REFS = [0.03, 0.03, 0.02, 0.02, 0.02, 0.02]


def _run(misses, u_answer=0.02):
    """A fit that returns the nominal paper calibration; answers miss their references by ``misses``."""
    def fit(touches, k):
        return replace(ProbeCalibration.nominal("paper"), created_utc="2026-11-27T00:00:00Z", calibrated=True)

    def remeasure(cal, j):
        e = E_REFS[j] * math.exp(misses[j])
        return e, e * math.hypot(u_answer, cal.u_rel_floor)   # the floor enters every answer in quadrature

    return checked_calibration(fit, list(range(len(NAMES))), NAMES, E_REFS, U_REFS, remeasure, force=True)


def _z(misses, cal, u_answer=0.02):
    return [abs(m) / math.hypot(math.hypot(u_answer, cal.u_rel_floor), u) for m, u in zip(misses, U_REFS)]


def test_a_reference_the_written_calibration_answers_outside_its_u_raises_the_floor_until_it_is_within():
    misses = [0.005, -0.004, 0.01, 0.0, -0.08, -0.02]     # AISI 304's first touch: z 2.8 without a floor
    assert max(_z(misses, ProbeCalibration.nominal("paper"))) > REFERENCE_Z
    cal, _ = _run(misses)
    z = _z(misses, cal)
    assert max(z) <= REFERENCE_Z * (1 + 1e-9)
    # The least such floor: the worst touch sits on the limit, and it is recorded.
    assert max(z) == pytest.approx(REFERENCE_Z, rel=1e-6)
    assert cal.self_check["remeasure_floor"] > 0.0
    assert cal.u_rel_floor >= cal.self_check["remeasure_floor"]
    # What the file reports for its references is what the device answers with it.
    aisi = next(r for r in cal.references if r.name == "aisi_304")
    assert aisi.rel_errors[0] == pytest.approx(math.exp(-0.08) - 1.0)


def test_references_within_their_u_leave_the_floor_as_the_self_check_set_it():
    misses = [0.005, -0.004, 0.01, 0.0, -0.02, 0.01]
    cal, check = _run(misses)
    assert "remeasure_floor" not in cal.self_check
    assert cal.u_rel_floor == pytest.approx(max(ProbeCalibration.nominal("paper").u_rel_floor, check.floor))
    assert max(_z(misses, cal)) <= REFERENCE_Z
