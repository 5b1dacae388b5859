"""edge.estimation.chain_estimate on FaithfulWorld records: from contact, flagged honestly.

The world is the independent (r, z) finite-volume probe (paper geometry), the record is what the
precision board reads, from 1 s in air before contact.
"""

from __future__ import annotations

import numpy as np
import pytest

from edge.estimation.chain_estimate import estimate_from_contact, uniform_record
from edge.physics.materials import load_materials
from firmware_sim.rigs.contact_record import ContactTouch, record_touch


@pytest.fixture(scope="module")
def lib():
    return load_materials()


@pytest.mark.parametrize("name", ["pmma", "borofloat_33"])
def test_a_touch_from_contact_is_within_its_stated_uncertainty(lib, name):
    r = record_touch(ContactTouch(lib.get(name).solid, 3e-5, -2.0, lead_s=1.5, heat_s=3.0), seed=3)
    d = estimate_from_contact(r["t_s"], r["T_C"], r["q_W_m2"])
    e = d["effusivity_W_s05_m2K"]
    assert abs(e - r["e_true"]) <= 1.96 * d["effusivity_W_s05_m2K_u"]
    assert d["contact_detected"] and d["contact_t_s"] == pytest.approx(-1.5, abs=0.06)
    assert d["object_temperature0"] == pytest.approx(r["T_obj0_C"], abs=3 * d["object_temperature0_u"] + 0.02)
    assert d["flags"] == ["uncalibrated"] and "e" in d["determined"]


@pytest.mark.parametrize("name", ["pmma", "aisi_304"])
def test_a_probe_lifted_while_heating_is_refused(lib, name):
    r = record_touch(ContactTouch(lib.get(name).solid, 1e-5, -1.0, lead_s=1.0, heat_s=2.0, lift_s=1.0), seed=1)
    d = estimate_from_contact(r["t_s"], r["T_C"], r["q_W_m2"])
    assert "contact_lost" in d["flags"] and d["effusivity_W_s05_m2K"] is None
    assert 1.0 <= d["contact_lost_t_s"] <= 1.5


def test_a_record_that_starts_in_contact_is_flagged_and_widened(lib):
    r = record_touch(ContactTouch(lib.get("borofloat_33").solid, 1e-5, -2.0, lead_s=2.0, heat_s=3.0), seed=4)
    keep = r["t_s"] >= -1.0          # the record starts 1 s after contact
    full = estimate_from_contact(r["t_s"], r["T_C"], r["q_W_m2"])
    late = estimate_from_contact(r["t_s"][keep], r["T_C"][keep], r["q_W_m2"][keep])
    assert "contact_not_recorded" in late["flags"] and "contact_not_recorded" not in full["flags"]
    assert late["u_e_parts"]["contact"] > 0
    # Widened enough to cover what starting mid-transient costs.
    assert abs(late["effusivity_W_s05_m2K"] - r["e_true"]) <= 1.96 * late["effusivity_W_s05_m2K_u"]


def test_uniform_record_resamples_jitter_and_refuses_gaps():
    rng = np.random.default_rng(0)
    t = np.arange(0, 2, 0.05) + rng.uniform(-0.004, 0.004, 40)
    tu, x = uniform_record(t, 2 * t)
    assert np.allclose(np.diff(tu), np.diff(tu)[0]) and np.allclose(x, 2 * tu)
    tg = np.concatenate([t[:10], t[12:]])
    with pytest.raises(ValueError, match="gap"):
        uniform_record(tg, tg)
    with pytest.raises(ValueError, match="increase"):
        uniform_record(t[::-1], t)
