"""``thermotouch calibrate`` and ``estimate --calibration`` on records of the faithful world.

Three reference touches of an as-built probe (sensitivity +4 %, sensing layer 6 % thicker, a 60-ms
bead) recorded from before contact are fitted; the calibrated probe then measures an unseen glass
touched 2 K warm with a contact resistance, closer than the datasheet probe does and within its stated
uncertainty.  Bad input: one line, exit 2, nothing written.
"""

from __future__ import annotations

import json
import math

import pytest

from edge.physics.materials import load_materials
from firmware_sim.rigs.contact_record import ContactTouch, one_d_geometry
from firmware_sim.rz.probe_world import AsBuilt
from host.records import write_series
from tests.support.records import recorded_touch
from tests.support.cli import run
from tests.support.faithful import DEVICE_DT_s, world_step

#: The tests that record, fit or measure are slow (the faithful world's touches, a calibration fit); the
#: refusals (hand-made records refused before any fit, a walk-through that finds no touch) run in the fast tier.

AS_BUILT = AsBuilt(sensing_thickness_m=0.424e-3, flux_sensitivity_V_per_W_m2=0.56e-6 * 1.04,
                   thermocouple_time_constant_s=0.06)
#: Heating of each recorded touch (s); test_calibrate_selfcheck.py's references are the same touches (one
#: simulation per session, tests/support/records.py).  4 s, not 6: the faithful world's touches 1.8 -> 1.5 CPU-s
#: and what is asserted keeps its margins (the calibrated glass +0.5 % against 3 % and a sixth of its 2 u,
#: where 6 s gave +0.3 %; the self-check's chi^2 0.33 against its limit 11.4, 0.14 at 6 s; the same
#: parameters determined by two and three references, the same refusal of the mis-declared reference).
HEAT_s = 4.0


@pytest.fixture(scope="module")
def records(tmp_path_factory):
    d = tmp_path_factory.mktemp("rec")
    lib = load_materials()
    out = {}
    for i, (name, rc, off) in enumerate((("pmma", 0.0, -1.0), ("pyroceram", 1e-5, 1.0), ("aisi_304", 0.0, 1.0),
                                         ("borofloat_33", 2e-5, 2.0))):
        r = recorded_touch(ContactTouch(lib.get(name).solid, rc, off, lead_s=1.0, heat_s=HEAT_s), as_built=AS_BUILT,
                         geometry=one_d_geometry(), seed=i)
        p = d / f"{name}.csv"
        write_series(p, r["t_s"], r["T_C"] + 273.15, r["q_W_m2"])
        out[name] = (p, r["e_true"])
    return out


@pytest.fixture
def device_world_step(faithful_world_test_step):
    """A simulated probe's world marching at ``DEVICE_DT_s`` (tests/support/faithful.py), twice the suite's step."""
    with world_step(DEVICE_DT_s):
        yield


@pytest.fixture(scope="module")
def record_files(tmp_path_factory):
    """Well-formed records for the refusals, which never reach a fit: the faithful ``records`` cost
    seconds, and a worker that runs only refusals need not simulate them."""
    import numpy as np

    d = tmp_path_factory.mktemp("files")
    t = np.arange(-40, 121) * 0.05                       # 2 s in air, contact at -1 s, heater-on at 0
    T = 25.0 + np.where(t > -1.0, 0.3, 0.0) + np.where(t > 0.0, 0.4 * np.sqrt(np.clip(t, 0, None)), 0.0)
    q = np.where(t > 0.0, 2500.0, 0.0)
    out = {}
    for name in ("pmma", "pyroceram"):
        p = d / f"{name}.csv"
        write_series(p, t, T + 273.15, q)
        out[name] = p
    return out


@pytest.mark.slow
# The same three records and references as test_calibrate_selfcheck.py's calibration: on one worker its fits are
# made once (edge.calibration.fit keeps them by their exact inputs).
@pytest.mark.shares_memo("calibration of the as-built records")
def test_fit_then_estimate_with_the_calibration_beats_the_datasheet(capsys, records, tmp_path):
    cal = tmp_path / "cal.json"
    args = []
    for name in ("pmma", "pyroceram", "aisi_304"):
        args += ["--record", str(records[name][0]), "--reference", name]
    code, out, err = run(capsys, "calibrate", *args, "--out", str(cal))
    assert code == 0, err
    assert "calibration" in out and "sensing depth" in out and cal.exists()
    # Refuses to overwrite without --overwrite, and the file stays.
    before = cal.read_bytes()
    code, _, err = run(capsys, "calibrate", *args, "--out", str(cal))
    assert code == 2 and "--overwrite" in err and cal.read_bytes() == before
    glass, e_true = records["borofloat_33"]
    # The record is the 1-D-limit world: tell the estimate nothing else (the paper probe's lateral
    # loss is negligible on glass at 4 s: alpha stays at the prior).
    code, out, err = run(capsys, "estimate", "--csv", str(glass), "--calibration", str(cal), "--json")
    assert code == 0, err
    d = json.loads(out)
    assert d["method"] == "sensor_chain" and "uncalibrated" not in d["flags"]
    err_cal = d["effusivity_W_s05_m2K"] / e_true - 1
    assert abs(err_cal) < 0.03 and abs(err_cal) * e_true <= 2 * d["effusivity_W_s05_m2K_u"]
    # One result shape (issue #33): the chain's own fields are under sensor_chain; a contact it did not
    # see in the record would be flagged contact_not_recorded.
    chain = d["sensor_chain"]
    assert "contact_not_recorded" not in chain["flags"] and chain["contact_t_s"] == pytest.approx(-1.0, abs=0.06)
    assert d["object"] is not None and d["candidates"]
    code, out, err = run(capsys, "estimate", "--csv", str(glass), "--calibration", str(cal))
    assert code == 0 and "method sensor_chain" in out and "sensor chain e " in out and "R_c " in out, err
    # The datasheet chain, through the same command without the calibration's file: flagged.
    code, out, err = run(capsys, "estimate", "--csv", str(glass), "--json")
    assert code == 0 and "uncalibrated" in json.loads(out)["flags"]


@pytest.mark.parametrize("argv,needle", [
    (["calibrate"], "give --record"),
    (["calibrate", "--record", "{pmma}", "--reference", "pmma"], "--out"),
    (["calibrate", "--record", "{pmma}", "--out", "{out}"], "one --reference per --record"),
    (["calibrate", "--record", "{pmma}", "--reference", "pmma", "--record", "{pyroceram}", "--reference",
      "unobtainium", "--out", "{out}"], "not a library material"),
    (["calibrate", "--record", "{pmma}", "--reference", "pmma", "--out", "{out}"], "at least two"),
    (["calibrate", "--check", "--sim", "glass_15V"], "exactly one --reference"),
    (["calibrate", "--show", "--record", "{pmma}", "--sim", "glass_15V"], "--show takes no"),
    (["calibrate", "--install", "{pmma}", "--sim", "glass_15V"], "--install"),
    (["estimate", "--csv", "{pmma}", "--calibration", "{pmma}"], "--calibration"),
    (["calibrate", "--sim", "alu_20V_faithful", "--reference", "pmma", "--out", "{out}"], "at least two"),
    (["calibrate", "--sim", "alu_20V_faithful", "--reference", "pmma", "--reference", "unobtainium", "--out",
      "{out}"], "not a library material"),
    (["calibrate", "--sim", "alu_20V_faithful"], "needs --out"),
    (["calibrate", "--sim", "alu_20V_faithful", "--arm", "500", "--out", "{out}"], "--arm"),
    (["calibrate", "--sim", "alu_20V_faithful", "--probe", "small-heater", "--out", "{out}"], "paper probe only"),
])
def test_bad_input_is_one_line_exit_2_and_nothing_written(capsys, record_files, tmp_path, argv, needle):
    out = tmp_path / "cal.json"
    fill = {"pmma": str(record_files["pmma"]), "pyroceram": str(record_files["pyroceram"]), "out": str(out)}
    code, _, err = run(capsys, *[a.format(**fill) for a in argv])
    assert code == 2 and needle in err, err
    assert len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_calibration_for_another_probe_is_refused(capsys, record_files, tmp_path):
    from tests.support.calibrations import sample_calibration

    p = tmp_path / "small.json"
    p.write_text(sample_calibration(probe="small-heater").to_json())
    code, _, err = run(capsys, "estimate", "--csv", str(record_files["pmma"]), "--calibration", str(p))
    assert code == 2 and "small-heater" in err and math.isfinite(1.0)


@pytest.mark.slow
@pytest.mark.usefixtures("device_world_step")
def test_walk_through_on_the_simulator_touches_each_reference_fits_writes_and_installs(capsys, tmp_path):
    # alu_20V_faithful: an as-built probe (thermopile +3 %, layer 3 % thinner, 4 % more conductive, a
    # 20-ms bead) on the precision board, dry contact.  Its world at DEVICE_DT_s: the walk-through's steps on
    # whatever records the device gets (the references re-measure -0.2 / +0.0 % at 40 ms, +0.1 / +0.3 % at the
    # suite's 20 ms; self-check passed at both) for 80 % of the test's CPU.  Each reference is that scene with
    # the reference as its object; the device is armed, finds the contact, heats; the host fits its raw records.
    out, work = tmp_path / "cal.json", tmp_path / "probe"
    code, text, err = run(capsys, "calibrate", "--sim", "alu_20V_faithful", "--workdir", str(work), "--reference",
                          "pmma", "--reference", "pyroceram", "--time", "2", "--out", str(out))
    assert code == 0, err
    assert text.count("reference ") == 2 and "written to" in text and "installed" in text
    cal = json.loads(out.read_text())
    # The references, re-measured with the fitted calibration, come back within a few per cent.
    assert all(abs(x) < 0.04 for r in cal["references"] for x in r["rel_errors"]), cal["references"]
    # Installed on that probe's storage: the next session of the same probe shows it.
    code, shown, err = run(capsys, "calibrate", "--show", "--sim", "alu_20V_faithful", "--workdir", str(work),
                           "--json")
    assert code == 0 and json.loads(shown)["sha256"] == cal["sha256"]


def test_walk_through_without_a_touch_stops_with_nothing_written_or_installed(capsys, tmp_path):
    # Armed for 0.3 s: the scene's touch comes at 1 s, so the device ends 'no_contact', heater never on.
    out, work = tmp_path / "cal.json", tmp_path / "probe"
    code, _, err = run(capsys, "calibrate", "--sim", "alu_20V_faithful", "--workdir", str(work), "--arm", "0.3",
                       "--out", str(out))
    assert code != 0 and "pmma: the touch ended no_contact: no touch within 0.3 s" in err
    assert len(err.strip().splitlines()) == 1 and not out.exists()
    code, shown, _ = run(capsys, "calibrate", "--show", "--sim", "alu_20V_faithful", "--workdir", str(work), "--json")
    assert code == 0 and json.loads(shown)["calibrated"] is False


@pytest.mark.slow
def test_small_heater_calibration_fits_the_flux_scale_and_estimate_uses_it(capsys, tmp_path):
    import numpy as np

    from edge.physics.axisym import AxisymModel
    from edge.physics.geometry import PROBES
    from host.records import write_record

    t = np.arange(251) * 0.02
    model = AxisymModel(PROBES["small-heater"], t)
    rng = np.random.default_rng(5)
    lib = load_materials()

    def rec(name):
        s = lib.get(name).solid
        T, q = model.signals(s.k_W_mK, s.alpha_m2_s)   # the thermopile reads 4 % low
        p = tmp_path / f"{name}.csv"
        write_record(p, t, T + 0.01 * rng.standard_normal(t.size), 0.96 * q + 0.5 * rng.standard_normal(t.size),
                     probe="small-heater")
        return str(p)

    cal = tmp_path / "small.json"
    code, out, err = run(capsys, "calibrate", "--probe", "small-heater", "--record", rec("pmma"), "--reference", "pmma",
                         "--record", rec("pyroceram"), "--reference", "pyroceram", "--out", str(cal))
    assert code == 0, err
    d = json.loads(cal.read_text())
    assert d["probe"] == "small-heater" and d["chain"]["flux_scale"] == pytest.approx(1 / 0.96, rel=0.01)
    glass = rec("borofloat_33")
    code, out, err = run(capsys, "estimate", "--probe", "small-heater", "--csv", glass, "--calibration", str(cal),
                         "--json")
    assert code == 0, err
    r = json.loads(out)
    assert "uncalibrated" not in r["flags"] and r["calibration_sha256"] == d["sha256"]
    # The calibrated path identifies the probe as built (flux scale, sensing layer, substrate) and fits the
    # touch's contact: k within its stated 95 % interval, which two one-touch references keep at a few per cent.
    u_k = r["k_W_mK_u"] / r["k_W_mK"]
    assert abs(np.log(r["k_W_mK"] / lib.get("borofloat_33").solid.k_W_mK)) < 1.96 * u_k and u_k < 0.05
    code, out, err = run(capsys, "estimate", "--probe", "small-heater", "--csv", glass, "--json")
    assert code == 0 and "uncalibrated" in json.loads(out)["flags"]
    # A paper-probe record is not a small-heater reference.
    code, _, err = run(capsys, "calibrate", "--probe", "small-heater", "--record", rec("pmma"), "--reference", "pmma",
                       "--record", str(tmp_path / "missing.csv"), "--reference", "pyroceram", "--out",
                       str(tmp_path / "x.json"))
    assert code == 2 and len(err.strip().splitlines()) == 1 and not (tmp_path / "x.json").exists()


@pytest.mark.slow
def test_a_small_heater_calibration_installed_on_the_device_is_applied_to_its_measurements(capsys, tmp_path):
    from tests.support.calibrations import sample_calibration

    cal = sample_calibration(probe="small-heater")
    p = tmp_path / "small.json"
    p.write_text(cal.to_json())
    work = str(tmp_path / "probe")
    # 1-s touches (the scene's profile heats 2.2 s): what is checked is whether the installed
    # calibration enters the estimate, not its accuracy, and half the faithful world's time is half the cost.
    code, out, err = run(capsys, "measure", "--sim", "glass_15V_small", "--workdir", work, "--time", "1", "--json")
    assert code == 0, err
    before = json.loads(out)
    assert "uncalibrated" in before["flags"] and before.get("calibration_sha256") is None
    code, _, err = run(capsys, "calibrate", "--install", str(p), "--sim", "glass_15V_small", "--workdir", work)
    assert code == 0, err
    code, out, err = run(capsys, "measure", "--sim", "glass_15V_small", "--workdir", work, "--time", "1", "--json")
    assert code == 0, err
    after = json.loads(out)
    assert "uncalibrated" not in after["flags"] and after["calibration_sha256"] == cal.sha256
    assert after["fit"]["flux_scale"] == pytest.approx(cal.chain.flux_scale)

