"""``thermotouch demo``: a simulated probe, a deployed model, the paper's nine touches, a table and plots.

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

__all__ = ["PAPER_SCENES", "TABLE2", "run_demo", "measure_scenes", "format_table", "build_then_move"]

PAPER_SCENES = ("glass_12V", "glass_15V", "glass_18V", "pmma_8V", "pmma_15V", "pmma_20V",
                "alu_15V", "alu_20V", "alu_25V")
#: Paper Table 2 (reference measurements): k (W/m/K), alpha (m^2/s) by sample.
TABLE2 = {"tempered glass": (1.097, 0.552e-6), "PMMA": (0.185, 0.110e-6), "Al alloy": (120.4, 51.9e-6)}
_SAMPLE_OF = {"glass": "tempered glass", "pmma": "PMMA", "alu": "Al alloy"}


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


def run_demo(out: str | Path = "thermotouch-demo", *, train: bool = False, scenes=PAPER_SCENES,
             progress: bool = True, overwrite: bool = False, log: Callable[[str], None] = print) -> int:
    """The demo (see the module docstring); returns the exit status.

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
    return build_then_move(out, lambda work: _demo_into(work, out, train=train, scenes=scenes, progress=progress,
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
    """The demo's run, written into ``out`` (the temporary sibling); messages name ``final``."""
    from host.deploy import DeployRefused, train_and_deploy  # noqa: PLC0415
    from host.flash import flash_bundle  # noqa: PLC0415
    from host.plots import PlotProcess  # noqa: PLC0415
    from host.progress import ProgressBar  # noqa: PLC0415

    workdir = out / "device"
    from thermotouch_models import DEFAULT_BUNDLE  # noqa: PLC0415

    # The plots are drawn in a child process from the start (it imports Matplotlib while the
    # model is flashed) to the end, on the other core, while the probe is touched.
    with PlotProcess() as plotter:
        log(f"ThermoTouch demo: simulated probe (storage {final / 'device'}), virtual serial link")
        with open_device(sim=scenes[0], workdir=workdir) as s:
            log(f"probe on {s.port}: board {s.client.info()['board']}")
            sha = None
            if train:
                log("training a quick model and deploying it if it is no worse than the probe's ...")
                try:
                    r = train_and_deploy(s, out / "model", quick=True, progress=progress, overwrite=overwrite,
                                         log=lambda m: log("  " + m))
                    sha = r["model_sha256"]
                except DeployRefused as exc:
                    log(f"  refused: {exc}")
                    log("  the demo continues with the model the probe runs")
            if sha is None:
                log(f"flashing the shipped model {DEFAULT_BUNDLE} ...")
                fl = flash_bundle(s, DEFAULT_BUNDLE, progress=progress)
                sha = fl["model_sha256"]
                log(f"  device reports sha256 {sha}")
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
