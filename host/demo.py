"""``thermotouch demo``: a simulated probe, a deployed model, the paper's nine touches, a table and plots.

By default (:func:`run_demo`) the probe is the instrument as a user meets it: a
paper probe DRAWN as built (:data:`DRAW_SEED`, the scene key ``[as_built]
draw_seed``: the simulator draws every unknown, the device is told only
the nominal values) on the faithful world (the ``*_faithful`` scenes' board and
sensors: the (r, z) finite-volume probe, never the estimator's model).  It is
calibrated by the README's walk-through -- the code ``thermotouch calibrate
--sim`` runs: armed touches of the default references
(:func:`host.calibration.touch_reference`), the fit, its leave-one-reference-out
self-check (:func:`host.calibration.checked_calibration`) and CALIBRATION_SET --
then the paper's samples are touched by hand (a contact resistance, an object
off the probe's temperature) and each answer is printed against the true value
with its 95 % interval, whether that interval holds the truth, the answer's
calibration and its flags.

With ``ideal=True`` (``--ideal``) it is the ideal-world demo below: the
estimator's own 1-D world, so its errors show the estimator, not an instrument.
One simulated probe with persistent storage (``OUT/device``) is powered up
on each of the paper's nine scenes in turn (tempered glass at 12/15/18 V,
PMMA at 8/15/20 V, aluminium alloy at 15/20/25 V). On the first, the model
is deployed over the virtual serial link: the shipped bundle is flashed, or
with ``train=True`` a quick bundle is trained and goes through
``thermotouch deploy``'s checks (it is refused if it does worse than the device's).
Each scene gets one touch through the same serial path a real probe uses;
the device's result (default method) is compared with the paper's Table 2
reference values, and the paper's method is run on the same record with the
same bundle. Plots go to ``OUT/plots``, the numbers to ``OUT/results.json``
and the table to ``OUT/table.txt``.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import shutil
import tempfile
import time
from pathlib import Path
from typing import Any, Callable

from firmware_sim.scene.files import PRECISION_BOARD, scene_variant
from host.atomic import write_text_atomic
from host.device import DeviceUnavailable, open_device

__all__ = ["PAPER_SCENES", "TABLE2", "DRAW_SEED", "run_demo", "measure_scenes", "format_table",
           "format_instrument_table", "build_then_move"]

PAPER_SCENES = ("glass_12V", "glass_15V", "glass_18V", "pmma_8V", "pmma_15V", "pmma_20V",
                "alu_15V", "alu_20V", "alu_25V")
#: Paper Table 2 (reference measurements): k (W/m/K), alpha (m^2/s) by sample.
TABLE2 = {"tempered glass": (1.097, 0.552e-6), "PMMA": (0.185, 0.110e-6), "Al alloy": (120.4, 51.9e-6)}
_SAMPLE_OF = {"glass": "tempered glass", "pmma": "PMMA", "alu": "Al alloy"}
#: The default demo's probe: ``[as_built] draw_seed`` (a fixed seed: every run draws the same probe).
DRAW_SEED = 1
#: The faithful scene whose board (precision: ADS122C04) and sensors the default demo's scenes take.
FAITHFUL_BASE = "alu_20V_faithful"
#: Heating of each walk-through reference touch (s): the walk-through's default is 8 s; 4 s is what the
#: demo's time allows and the self-check accepts (its references re-measure within ~2 %; 2 s: ~6 %).
REFERENCE_HEAT_s = 3.0
#: The hand touch per sample (contact resistance m^2K/W, object minus probe K): a dry hand-pressed
#: contact and an object off the probe's temperature, resting 1 s before the heating.
#: The default demo's touches: one per paper sample at its middle voltage (the nine with ``scenes=PAPER_SCENES``).
SAMPLE_SCENES = ("glass_15V", "pmma_15V", "alu_20V")
HAND_TOUCH = {"glass": (2.0e-5, -1.5), "pmma": (1.0e-5, 1.0), "alu": (3.0e-5, -1.0)}


def _err(v, ref):
    return None if v is None else (v - ref) / ref


def measure_scenes(workdir: Path, scenes=PAPER_SCENES, *, plots: Path | None = None,
                   plotter: Any = None, expect_sha256: str | None = None, log: Callable[[str], None] = print,
                   progress: Callable[[int, int], None] | None = None) -> list[dict]:
    """One touch per scene on a simulated probe whose storage is ``workdir``; rows of results.

    Each row holds the scene, the reference solid, the device's result, the
    paper-method result on the same record, errors, flags and the heater
    invariant of that power-up. With ``plots`` (a directory) each touch is
    also drawn to ``plots/<scene>.png`` by ``plotter`` (a
    :class:`host.plots.PlotProcess`, which writes them by its ``close``), or
    by a plot process of this call's own, closed before returning.
    """
    from host.plots import PlotProcess  # noqa: PLC0415

    rows = []
    with contextlib.ExitStack() as stack:
        if plots is not None:
            Path(plots).mkdir(parents=True, exist_ok=True)
            if plotter is None:
                plotter = stack.enter_context(PlotProcess())
        for i_scene, scene_ref in enumerate(scenes):
            rows.append(_measure_scene(workdir, scene_ref, plots, plotter, expect_sha256, log))
            if progress is not None:
                progress(i_scene + 1, len(scenes))
    return rows


def _measure_scene(workdir: Path, scene_ref, plots: Path | None, plotter, expect_sha256: str | None,
                   log: Callable[[str], None]) -> dict:
    """One touch on a fresh power-up of the scene's probe; its row (and its plot when ``plots``)."""
    from host.touch import touch  # noqa: PLC0415

    scene = Path(scene_ref).stem  # a shipped name or a generated variant's path
    with open_device(sim=str(scene_ref), workdir=workdir) as s:
        sha = s.client.info()["model_sha256"]
        if expect_sha256 is not None and sha != expect_sha256:
            raise DeviceUnavailable(f"{scene}: device runs model {sha}, expected {expect_sha256}")
        t = touch(s, method="default", with_series=True)
        limit = s.daemon.config.heater.max_on_time_s
    inv = s.simulator.heater_invariant(limit)
    solid = s.simulator.scene.object.solid
    r = t.result
    paper = t.fits.get("paper")
    row = {
        "scene": scene, "sample": _SAMPLE_OF[scene.split("_")[0]], "measurement_id": t.record["measurement_id"],
        "power_W": t.record["power_W"], "model_sha256": r["model_sha256"],
        "ref": {"e": solid.effusivity_W_s05_m2K, "k": solid.k_W_mK, "alpha": solid.alpha_m2_s},
        "default": {"e": r["effusivity_W_s05_m2K"], "e_u": r["effusivity_W_s05_m2K_u"], "k": r["k_W_mK"],
                    "k_u": r["k_W_mK_u"], "alpha": r["alpha_m2_s"], "alpha_u": r["alpha_m2_s_u"],
                    "material": r["material"], "material_confidence": r["material_confidence"]},
        "paper": None if paper is None else {"e": paper.effusivity_W_s05_m2K, "k": paper.k_W_mK,
                                             "alpha": paper.alpha_m2_s, "flags": list(paper.flags)},
        "flags": list(t.record.get("flags") or []),
        "method": r.get("method"), "calibration_sha256": r.get("calibration_sha256"),
        "heater": {"ok": inv["ok"], "longest_on_s": inv["longest_on_s"], "off_now": inv["off_now"],
                   "limit_s": limit},
    }
    for m in ("default", "paper"):
        if row[m] is not None:
            row[m]["errors"] = {q: _err(row[m][q], row["ref"][q]) for q in ("e", "k", "alpha")}
    if plots is not None:
        from host.plot_data import touch_identity  # noqa: PLC0415

        d = dict(r, **touch_identity(t.record))   # the title identifies the measurement
        d["flags"] = row["flags"]
        row["plot"] = str(plotter.submit(plots / f"{scene}.png", t.series, d, t.fits.get("default"), scene))
    log(f"  {scene:10} e = {_num(r['effusivity_W_s05_m2K'])} ({_pct(row['default']['errors']['e']).strip()})"
        + (f", flags: {', '.join(row['flags'])}" if row["flags"] else ""))
    return row


def _int(x):
    return "-" if x is None else f"{x:.0f}"


def _pct(x):
    return "    -  " if x is None or not math.isfinite(x) else f"{x * 100:+6.1f}%"


def _num(x, scale=1.0, w=0):
    return ("-" if x is None else f"{x * scale:.4g}").rjust(w)


def format_table(rows: list[dict]) -> str:
    """The per-touch table and the per-sample summary against Table 2."""
    lines = []
    width = max([10] + [len(r["scene"]) for r in rows])
    hdr = (f"{'scene':10} {'e ref':>7} {'e':>7} {'err':>7} │ {'k ref':>6} {'k':>7} {'err':>7} │ "
           f"{'α ref':>6} {'α':>7} {'err':>7} │ {'paper: k':>8} {'α err':>7} │ {'material (default)':22} flags")
    lines.append("Per touch — default method on the device; paper method on the same record (errors only).")
    lines.append("e in W s^0.5/(m² K), k in W/(m K), α in mm²/s; references: paper Table 2.")
    lines.append(hdr.replace(f"{'scene':10}", f"{'scene':{width}}"))
    lines.append("─" * (len(hdr) + width - 10))
    for r in rows:
        d, p, ref = r["default"], r["paper"] or {}, r["ref"]
        pe = p.get("errors", {})
        lines.append(
            f"{r['scene']:{width}} {ref['e']:7.0f} {_int(d['e']):>7} {_pct(d['errors']['e'])} │ "
            f"{ref['k']:6.4g} {_num(d['k']):>7} {_pct(d['errors']['k'])} │ "
            f"{ref['alpha'] * 1e6:6.3g} {_num(d['alpha'], 1e6):>7} {_pct(d['errors']['alpha'])} │ "
            f"{_pct(pe.get('k')):>8} {_pct(pe.get('alpha'))} │ {str(d['material'] or '-'):22} {', '.join(r['flags']) or '-'}")
    lines.append("")
    lines.append("Per sample (mean over its three voltages) against Table 2:")
    h2 = (f"{'sample':15} {'k ref':>7} {'k default':>17} {'k paper':>17} │ {'α ref':>6} {'α default':>15} "
          f"{'α paper':>15}")
    lines.append(h2)
    lines.append("─" * len(h2))
    for sample, (k_ref, a_ref) in TABLE2.items():
        sel = [r for r in rows if r["sample"] == sample]
        if not sel:
            continue

        def mean(method, q):
            v = [r[method][q] for r in sel if r[method] is not None and r[method][q] is not None]
            return sum(v) / len(v) if v else None

        def cell(v, ref, scale=1.0, w=17):
            return f"{'-':>{w}}" if v is None else f"{v * scale:.4g} ({_pct(_err(v, ref)).strip()})".rjust(w)

        lines.append(f"{sample:15} {k_ref:7.4g} {cell(mean('default', 'k'), k_ref)} {cell(mean('paper', 'k'), k_ref)} │ "
                     f"{a_ref * 1e6:6.3g} {cell(mean('default', 'alpha'), a_ref, 1e6, 15)} "
                     f"{cell(mean('paper', 'alpha'), a_ref, 1e6, 15)}")
    return "\n".join(lines)


def run_demo(out: str | Path = "thermotouch-demo", *, train: bool = False, scenes=None,
             progress: bool = True, overwrite: bool = False, ideal: bool = False,
             log: Callable[[str], None] = print) -> int:
    """The demo (see the module docstring); returns the exit status.

    ``ideal``: the ideal-world demo (the estimator's 1-D world, both boards); otherwise the drawn
    as-built probe, calibrated, touching ``scenes`` on the faithful world.  ``scenes``: default
    :data:`PAPER_SCENES` (ideal) or :data:`SAMPLE_SCENES`.

    ``out`` must not exist unless ``overwrite`` (then its simulated probe
    storage ``out/device`` is reset, and the demo's files are replaced).

    Raises
    ------
    FileExistsError
        ``out`` exists and ``overwrite`` is false.
    NotADirectoryError
        ``out`` exists and is not a directory.
    host.device.DeviceUnavailable
        The run failed (exit status 1); nothing was written to ``out``.
    """
    t0 = time.perf_counter()
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(f"{out} exists and is not a directory")
    if out.exists() and not overwrite:
        raise FileExistsError(f"{out} exists (use --overwrite to replace it)")
    demo = _demo_into if ideal else _instrument_into
    if scenes is None:
        scenes = PAPER_SCENES if ideal else SAMPLE_SCENES
    return build_then_move(out, lambda work: demo(work, out, train=train, scenes=scenes, progress=progress,
                                                  overwrite=overwrite, log=log, t0=t0))


def build_then_move(out: Path, build: Callable[[Path], Any]) -> Any:
    """``build(work)`` in a hidden sibling of ``out``, then its entries moved into ``out``; its return value.

    A run that fails (a full disk, a device that stops) leaves nothing behind that would block the rerun:
    the sibling is removed and the failure raised as :class:`host.device.DeviceUnavailable` with exit
    status 1 -- inside the demo every input is its own (shipped scenes, its own variants), so even a file
    the device calls invalid is a runtime failure, not the user's input.
    """
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix=".thermotouch-demo-partial-", dir=out.parent))
    try:
        result = build(work)
        _move_into(work, out)
    except (OSError, DeviceUnavailable) as exc:
        shutil.rmtree(work, ignore_errors=True)
        why = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        where = f"{exc.filename}: " if isinstance(exc, OSError) and exc.filename else ""
        raise DeviceUnavailable(f"demo failed, nothing written to {out}: {where}{why}", 1) from None
    except BaseException:
        shutil.rmtree(work, ignore_errors=True)
        raise
    return result


def _move_into(work: Path, out: Path) -> None:
    """Move the finished run from ``work`` to ``out``: a rename, or (``out`` exists: --overwrite) each of the
    demo's own entries replaced, the user's other files in ``out`` kept."""
    if not out.exists():
        os.replace(work, out)
        return
    for child in work.iterdir():
        dest = out / child.name
        if dest.is_dir() and not dest.is_symlink():
            shutil.rmtree(dest)
        elif os.path.lexists(dest):
            dest.unlink()
        os.replace(child, dest)
    work.rmdir()


def _demo_into(out: Path, final: Path, *, train: bool, scenes, progress: bool, overwrite: bool,
               log: Callable[[str], None], t0: float) -> int:
    """The ideal-world demo's run, written into ``out`` (the temporary sibling); messages name ``final``."""
    from host.plots import PlotProcess  # noqa: PLC0415
    from host.progress import ProgressBar  # noqa: PLC0415

    workdir = out / "device"
    # The plots are drawn in a child process from the start (it imports Matplotlib while the
    # model is flashed) to the end, on the other core, while the probe is touched.
    with PlotProcess() as plotter:
        log(f"ThermoTouch demo: simulated probe (storage {final / 'device'}), virtual serial link")
        with open_device(sim=scenes[0], workdir=workdir) as s:
            log(f"probe on {s.port}: board {s.client.info()['board']}")
            sha = _deploy(s, out, train=train, progress=progress, overwrite=overwrite, log=log)
        # The self-check (with --train) used the first scene's touch; every scene gets a fresh power-up.
        log(f"touching the paper's samples ({len(scenes)} scenes) ...")
        with ProgressBar("touches", "touch", enabled=progress) as bar:
            rows = measure_scenes(workdir, scenes, plots=out / "plots", plotter=plotter, expect_sha256=sha,
                                  log=log, progress=bar)
        # The paper read its sensors with a precision DMM; the same nine touches on the
        # precision board (24-bit ADS122C04 for thermocouple and flux) show what that buys.
        log("the same nine touches on the precision board (ADS122C04) ...")
        variants = [scene_variant(sc, out / "scenes", suffix="_precision", board=PRECISION_BOARD) for sc in scenes]
        with ProgressBar("touches", "touch", enabled=progress) as bar:
            # Table only: the reference board's plots show the touches (nine more would outlast the touches).
            rows_p = measure_scenes(workdir, variants, expect_sha256=sha, log=log, progress=bar)
    table = ("Reference board (MCP9600 thermocouple converter, ADS1115 flux ADC):\n" + format_table(rows)
             + "\n\nPrecision board (ADS122C04 for thermocouple EMF and flux):\n" + format_table(rows_p))
    log("")
    log(table)
    write_text_atomic(out / "table.txt", table + "\n")
    write_text_atomic(out / "results.json", json.dumps({"model_sha256": sha, "rows": rows, "rows_precision": rows_p},
                                                       indent=1))
    rows = rows + rows_p
    heater_ok = all(r["heater"]["ok"] for r in rows)
    log("")
    log(f"heater invariant held on every touch: {'yes' if heater_ok else 'NO'}; "
        f"plots in {final / 'plots'}/, numbers in {final / 'results.json'}; {time.perf_counter() - t0:.1f} s")
    log(f"the probe's history: thermotouch history --sim glass_15V --workdir {final / 'device'}")
    return 0 if heater_ok else 1


def _deploy(s, out: Path, *, train: bool, progress: bool, overwrite: bool, log: Callable[[str], None]) -> str:
    """The model on the probe of session ``s``: a quick trained one (``train``, if no worse) or the shipped one."""
    from host.deploy import DeployRefused, train_and_deploy  # noqa: PLC0415
    from host.flash import flash_bundle  # noqa: PLC0415
    from thermotouch_models import DEFAULT_BUNDLE  # noqa: PLC0415

    if train:
        log("training a quick model and deploying it if it is no worse than the probe's ...")
        try:
            r = train_and_deploy(s, out / "model", quick=True, progress=progress, overwrite=overwrite,
                                 log=lambda m: log("  " + m))
            return r["model_sha256"]
        except DeployRefused as exc:
            log(f"  refused: {exc}")
            log("  the demo continues with the model the probe runs")
    log(f"flashing the shipped model {DEFAULT_BUNDLE} ...")
    sha = flash_bundle(s, DEFAULT_BUNDLE, progress=progress)["model_sha256"]
    log(f"  device reports sha256 {sha}")
    return sha


def instrument_scenes(scenes, dest: Path, *, draw_seed: int = DRAW_SEED) -> tuple[Path, list[Path]]:
    """The drawn probe's scenes: the walk-through's base, and each paper scene touched by hand on the faithful world.

    Every scene takes :data:`FAITHFUL_BASE`'s board and sensors and ``[as_built] draw_seed``; a paper
    scene keeps its object and heater voltage and gets the hand touch of :data:`HAND_TOUCH`.
    """
    import tomllib  # noqa: PLC0415

    from firmware_sim.scene.files import scene_path  # noqa: PLC0415

    base = tomllib.loads(scene_path(FAITHFUL_BASE).read_text())
    tables = {"board": base["board"], "sensors": base["sensors"], "as_built": {"draw_seed": draw_seed}}
    walk = scene_variant(FAITHFUL_BASE, dest, suffix=f"_drawn{draw_seed}", as_built=tables["as_built"])
    out = []
    for sc in scenes:
        R_c, offset_K = HAND_TOUCH[Path(sc).stem.split("_")[0]]
        touch = {"start_s": 0.5, "length_s": 3.5, "contact_lead_s": 1.0, "contact_resistance_m2K_W": R_c,
                 "object_offset_K": offset_K}
        out.append(scene_variant(sc, dest, suffix="_asbuilt", touch=touch, **tables))
    return walk, out


def walk_through(walk: Path, scenes_dir: Path, workdir: Path, *, deploy: Callable[[Any], str],
                 heat_s: float = REFERENCE_HEAT_s, log: Callable[[str], None] = print) -> dict:
    """``thermotouch calibrate --sim WALK``'s walk-through on the drawn probe: touch, fit, self-check, install.

    ``deploy(session)`` puts the model on the probe (on the first reference's power-up) and returns its
    sha256.  A calibration its self-check refuses is said so in one line and installed forced (flagged,
    with the floor that covers its misses), so the touches still show what the probe would answer.
    Returns ``model_sha256``, ``calibration`` (a ProbeCalibration), ``check`` (its SelfCheck) and ``refused``.
    """
    from edge.calibration.fit import DEFAULT_REFERENCES, OTHER_REFERENCE_U_REL, REFERENCE_U_REL  # noqa: PLC0415
    from edge.calibration.fit import fit_calibration  # noqa: PLC0415
    from edge.calibration.model import CalibrationError  # noqa: PLC0415
    from edge.physics.materials import load_materials  # noqa: PLC0415
    from host.calibration import (CalibrationRefused, WalkError, checked_calibration, install_calibration,  # noqa: PLC0415
                                  reference_scene, seam_remeasure, touch_reference)
    from edge.estimation.estimate import Estimator  # noqa: PLC0415
    from edge.estimation.seam import SeamContext  # noqa: PLC0415
    from edge.service.config import Config  # noqa: PLC0415
    from host.touch import host_bundle  # noqa: PLC0415

    lib = load_materials()
    names = list(DEFAULT_REFERENCES)
    e_refs = [lib.get(n).solid.effusivity_W_s05_m2K for n in names]
    u_refs = [REFERENCE_U_REL.get(n, OTHER_REFERENCE_U_REL) for n in names]
    touches, records, sha, out = [], [], None, {}
    for i, (name, e_ref) in enumerate(zip(names, e_refs)):
        path = reference_scene(str(walk), name, scenes_dir, heat_s=heat_s)
        with open_device(sim=str(path), workdir=workdir) as s:
            if sha is None:
                sha = deploy(s)
            try:
                t, rec, record = touch_reference(s.client, name, e_ref, heat_s=heat_s)
            except WalkError as exc:   # the demo's own scenes: a failed touch is a runtime failure
                raise DeviceUnavailable(f"calibration walk-through: {exc}", 1) from None
            touches.append(t)
            records.append(record)
            log(f"  reference {i + 1}/{len(names)} {name} (e {e_ref:.0f}): measurement {rec['measurement_id']}, "
                f"{t.t_s.size} samples")
            if i + 1 < len(names):
                continue
            # The self-check re-measures each reference as the device answers: its model, default thresholds.
            bundle, note = host_bundle(sha, session=s)
            if bundle is None:
                raise DeviceUnavailable(f"calibration walk-through: no bundle to re-measure with ({note})", 1)
            ctx = SeamContext(estimator=Estimator.from_bundle(bundle), calibration=None,
                              thresholds=Config().measurement)
            remeasure = seam_remeasure(records, [ctx] * len(records))

            def fit(tt, k):
                return fit_calibration(tt, probe="paper", min_references=k)
            device_id = s.client.info().get("device_id")
            try:
                try:
                    cal, check = checked_calibration(fit, touches, names, e_refs, u_refs, remeasure,
                                                     device_id=device_id)
                    out["refused"] = None
                except CalibrationRefused as exc:
                    out["refused"] = str(exc)
                    log(f"  {exc}")
                    log("  the demo installs it forced (flagged 'forced', its floor covers the misses)")
                    cal, check = checked_calibration(fit, touches, names, e_refs, u_refs, remeasure, force=True,
                                                     device_id=device_id)
            except (CalibrationError, ValueError) as exc:
                raise DeviceUnavailable(f"calibration walk-through: the fit failed: {exc}", 1) from None
            install_calibration(s.client, cal)
    out.update(model_sha256=sha, calibration=cal, check=check)
    return out


def _calibration_lines(cal, check) -> list[str]:
    c = cal.chain
    refs = "; ".join(f"{r.name} " + ", ".join(f"{x:+.1%}" for x in r.rel_errors) for r in cal.references)
    return [f"calibration {cal.sha256[:12]}{' (FORCED)' if cal.forced else ''}: flux sensitivity x "
            f"{1.0 / c.flux_scale:.4f} of nominal, sensing depth {c.sensing_thickness_m * 1e3:.4f} mm, layer k "
            f"{c.k_W_mK:.4f} W/m/K, thermocouple lag {c.tc_tau_s * 1e3:.1f} ms, model-form floor on e "
            f"{cal.u_rel_floor:.1%}",
            f"  {check.line()}",
            f"  references re-measured with it: {refs}"]


def format_instrument_table(rows: list[dict], cal_sha256: str | None) -> str:
    """Per touch: the true e, the answer ± u, its error, its 95 % interval and whether it holds the truth."""
    width = max([10] + [len(r["scene"]) for r in rows])
    hdr = (f"{'scene':{width}} {'true e':>7} {'e ± u':>13} {'err':>7} │ {'95 % interval':>15} {'holds':>5} │ "
           f"{'k err':>7} {'α err':>7} │ {'answered':10} flags")
    lines = ["e in W s^0.5/(m² K); true = the simulated object's; interval e ± 1.96 u; k and α of the paper "
             "probe come from the library prior.", hdr, "─" * len(hdr)]
    held = answered = 0
    for r in rows:
        d, e_true = r["default"], r["ref"]["e"]
        e, u = d["e"], d["e_u"]
        if e is None or u is None:
            cells = f"{'-':>13} {'-':>7} │ {'-':>15} {'-':>5}"
        else:
            lo, hi = e - 1.96 * u, e + 1.96 * u
            holds = lo <= e_true <= hi
            held += holds
            answered += 1
            cells = (f"{f'{e:.0f} ± {u:.0f}':>13} {_pct(d['errors']['e'])} │ {f'{lo:.0f}–{hi:.0f}':>15} "
                     f"{'yes' if holds else 'NO':>5}")
        how = ("calibrated" if cal_sha256 is not None and r.get("calibration_sha256") == cal_sha256
               and "uncalibrated" not in r["flags"] else "NOT calib.")
        lines.append(f"{r['scene']:{width}} {e_true:7.0f} {cells} │ {_pct(d['errors']['k'])} "
                     f"{_pct(d['errors']['alpha'])} │ {how:10} {', '.join(r['flags']) or '-'}")
    lines.append(f"{answered} of {len(rows)} touches answered; the 95 % interval holds the true e on {held} of them.")
    return "\n".join(lines)


def _instrument_into(out: Path, final: Path, *, train: bool, scenes, progress: bool, overwrite: bool,
                     log: Callable[[str], None], t0: float) -> int:
    """The default demo's run (module docstring), written into ``out``; messages name ``final``."""
    from host.plots import PlotProcess  # noqa: PLC0415
    from host.progress import ProgressBar  # noqa: PLC0415

    workdir = out / "device"
    with PlotProcess() as plotter:
        log(f"ThermoTouch demo: a paper probe drawn as built ([as_built] draw_seed = {DRAW_SEED}: the device is told "
            f"only its nominal values) on the faithful world, precision board; storage {final / 'device'}")
        walk, variants = instrument_scenes(scenes, out / "scenes")
        log(f"calibrating it by the walk-through (thermotouch calibrate --sim): {REFERENCE_HEAT_s:g}-s touches of "
            "the references ...")
        w = walk_through(walk, out / "scenes", workdir, log=log,
                         deploy=lambda s: _deploy(s, out, train=train, progress=progress, overwrite=overwrite,
                                                  log=lambda m: log("  " + m)))
        cal, check, sha = w["calibration"], w["check"], w["model_sha256"]
        cal_lines = _calibration_lines(cal, check)
        log(f"  calibration {cal.sha256[:12]} installed{' FORCED' if cal.forced else ''} "
            f"(self-check {'passed' if check.passed else 'FAILED'}; in full with the table below)")
        log(f"touching the paper's samples by hand with the calibrated probe ({len(scenes)} scenes) ...")
        with ProgressBar("touches", "touch", enabled=progress) as bar:
            rows = measure_scenes(workdir, variants, plots=out / "plots", plotter=plotter, expect_sha256=sha,
                                  log=log, progress=bar)
    table = "\n".join(cal_lines) + "\n\n" + format_instrument_table(rows, cal.sha256)
    log("")
    log(table)
    write_text_atomic(out / "table.txt", table + "\n")
    write_text_atomic(out / "results.json", json.dumps(
        {"mode": "as_built", "draw_seed": DRAW_SEED, "faithful_base": FAITHFUL_BASE, "model_sha256": sha,
         "reference_heat_s": REFERENCE_HEAT_s, "calibration": cal.to_dict(), "calibration_sha256": cal.sha256,
         "refused": w["refused"], "self_check": check.to_dict(), "rows": rows}, indent=1))
    heater_ok = all(r["heater"]["ok"] for r in rows)
    log("")
    log(f"heater invariant held on every touch: {'yes' if heater_ok else 'NO'}; "
        f"plots in {final / 'plots'}/, numbers in {final / 'results.json'}; {time.perf_counter() - t0:.1f} s")
    log(f"the probe's history: thermotouch history --sim {FAITHFUL_BASE} --workdir {final / 'device'}; "
        "the ideal-world demo: thermotouch demo --ideal")
    return 0 if heater_ok else 1
