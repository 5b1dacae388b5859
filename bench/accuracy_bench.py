"""What accuracy to expect, per probe head and board: the README's one table, from results already measured.

Nothing is simulated here: every row is read from a bench's results file in bench/results/ (the long
benches are not rerun), so the table changes exactly when one of them is rerun.

* paper probe, ideal contact (``estimation.json``, ``lomo_default``): every library material touched
  once for 2 s (q_v 7.7e7 W/m^3) on the exact model, with that material left out of the prior;
* paper probe, a real contact (``calibration.json``, ``calibration_reference.json``): 8 as-built
  probes x 20 library solids on the faithful world, R_c up to 1e-4 m^2K/W, the object -3..+3 K off
  the probe, 10-s heating; the datasheet sensor chain (uncalibrated) and the calibrated one; results
  flagged ``poor_fit`` are refused (not answered); k and α then come from the library prior given e;
* small-heater probe (``small_probe.json``, ``small_probe_reference.json``): 20 synthetic solids off
  the library, ideal contact, a calibrated thermopile (2 % spread); e from each touch's fitted k and α.
* both heads, drawn as-built probes (``asbuilt.json``): 8 probes per head drawn from realistic
  tolerances (firmware_sim/asbuilt.py: sensitivity, the sensor's real square footprint and offset,
  sensing layer, substrate, thermocouple, heater) that the device is never told, 4 solids (glass, PMMA,
  steel, copper), ideal contact, 2 s, UNCALIBRATED: what an as-built probe answers before a
  calibration that identifies it (ISSUE #34), with the share of 95 % intervals that hold the truth;
* both heads, drawn as-built probes CALIBRATED by the walk-through's references and touched by hand
  (``asbuilt_calibrated.json``, ``asbuilt_small.json``): R_c 0-1e-4 m^2K/W, object -3..+3 K off the probe,
  contact 0.5-3 s before heating, 20 solids foam to copper not used for calibration; unanswered touches
  (the calibrated chain refused them) are counted in "answered". A second table gives the paper probe's
  short windows per class of solid against the attainable u (``thermotouch design``'s Fisher limit).

Errors are |relative error| of the answered touches: median [90th percentile].

Run:  python bench/accuracy_bench.py [--update-readme]
Prints the table; --update-readme writes it between ``<!-- accuracy:begin -->`` and
``<!-- accuracy:end -->`` in README.md.
"""

from __future__ import annotations

import argparse
import json
import math

import numpy as np

from _common import RESULTS, update_readme

BOARDS = {"ads122c04": "precision (ADS122C04)", "mcp9600": "reference (MCP9600 + ADS1115)",
          "precision": "precision (ADS122C04)", "reference": "reference (MCP9600 + ADS1115)"}


def _load(name: str) -> dict:
    return json.loads((RESULTS / f"{name}.json").read_text())


def _stats(errs) -> tuple[float, float] | None:
    """Median and 90th percentile of |relative error|, or None without answers."""
    a = np.abs(np.asarray([e for e in errs if e is not None and math.isfinite(e)], float))
    return (float(np.median(a)), float(np.percentile(a, 90))) if a.size else None


def _fmt(s) -> str:
    if s is None:
        return "-"
    if isinstance(s, str):
        return s
    med, p90 = s
    return f"{_pct(med)} [{_pct(p90)}]"


def _pct(x: float) -> str:
    x *= 100
    return f"{x:.2f} %" if x < 1 else f"{x:.1f} %" if x < 10 else f"{x:.0f} %"


def paper_ideal_rows(est: dict) -> list[dict]:
    """Paper probe, ideal contact, default method, each library material left out of the prior."""
    n_total = int(est["manifest_metrics"]["n_materials"])
    rows = []
    for inst in ("ads122c04", "mcp9600"):
        s = est["lomo_default"][inst]
        rows.append(dict(probe="paper", board=BOARDS[inst], touch="ideal contact, 2 s, uncalibrated",
                         answered=f"{s['e']['n']}/{n_total}",
                         e=(s["e"]["median"], s["e"]["p90"]), k=(s["k"]["median"], s["k"]["p90"]),
                         alpha=(s["alpha"]["median"], s["alpha"]["p90"]), kalpha="prior given e",
                         source="estimation_bench.py"))
    return rows


def paper_real_rows(cal: dict, board: str, chains=("datasheet", "calibrated")) -> list[dict]:
    """Paper probe (its 55 x 60 mm heater on foam) on the faithful world, per sensor chain."""
    rows = []
    for chain in chains:
        sel = [r for r in cal["rows"] if r["geometry"] == "paper" and r["chain"] == chain]
        ok = [r for r in sel if "poor_fit" not in r["flags"] and r.get("e") is not None]
        label = "uncalibrated (datasheet chain)" if chain == "datasheet" else "calibrated chain"
        rows.append(dict(probe="paper", board=BOARDS[board],
                         touch=f"real contact, {cal['heat_s']:g} s, {label}", answered=f"{len(ok)}/{len(sel)}",
                         e=_stats([r["e"] / r["e_true"] - 1.0 for r in ok]), k="prior", alpha="prior",
                         kalpha="prior given e", source="calibration_bench.py"))
    return rows


def small_heater_rows(sp: dict, contacts=("2s", "5s")) -> list[dict]:
    """Small-heater probe, ideal contact: k and α fitted; e from them."""
    rows = []
    for c in contacts:
        ct = float(c.rstrip("s"))
        sel = [r for r in sp["rows"] if r["probe"] == "small-heater" and r["contact_time_s"] == ct]
        ok = [r for r in sel if r.get("err_k") is not None and r.get("err_alpha") is not None]
        summ = sp["summary"]["small-heater"][c]
        e_err = [(1.0 + r["err_k"]) / math.sqrt(1.0 + r["err_alpha"]) - 1.0 for r in ok]
        rows.append(dict(probe="small-heater", board=BOARDS[sp["board"]], touch=f"ideal contact, {ct:g} s, calibrated",
                         answered=f"{len(ok)}/{len(sel)}", e=_stats(e_err), k=_stats([r["err_k"] for r in ok]),
                         alpha=_stats([r["err_alpha"] for r in ok]),
                         kalpha=f"measured on {summ['determined_pct']:.0f} %", source="small_probe_bench.py"))
    return rows


def asbuilt_rows(ab: dict) -> list[dict]:
    """Drawn as-built probes (never the nominal one), uncalibrated, per head."""
    rows = []
    for head in ab["heads"]:
        sel = [r for r in ab["rows"] if r["head"] == head and str(r["probe"]).startswith("draw")]
        ok = [r for r in sel if r.get("err_effusivity_W_s05_m2K") is not None]
        cov = [abs(r["err_effusivity_W_s05_m2K"]) <= 1.96 * r["u_rel_effusivity_W_s05_m2K"] for r in ok
               if r.get("u_rel_effusivity_W_s05_m2K") is not None]
        n_probes = len({r["probe"] for r in sel})

        def errs(q):
            return [r.get(f"err_{q}") for r in ok]

        det = sum(1 for r in ok if r.get("determined") and "k" in r["determined"])
        rows.append(dict(probe=head, board=BOARDS["precision"],
                         touch=f"{n_probes} drawn as-built probes, ideal contact, {ab['heat_s']:g} s, uncalibrated; "
                               f"95 % interval holds e on {100 * sum(cov) / max(1, len(cov)):.0f} %",
                         answered=f"{len(ok)}/{len(sel)}", e=_stats(errs("effusivity_W_s05_m2K")),
                         k=_stats(errs("k_W_mK")), alpha=_stats(errs("alpha_m2_s")),
                         kalpha="prior given e" if head == "paper" else f"measured on {100 * det / max(1, len(ok)):.0f} %",
                         source="asbuilt_bench.py"))
    return rows


def _rel_stats(rs: list[dict], err_key: str) -> tuple[float, float] | None:
    return _stats([r.get(err_key) for r in rs])


def calibrated_asbuilt_rows(ac: dict, small: dict) -> list[dict]:
    """Drawn as-built probes calibrated by the walk-through, hand touches: paper per window, small head per heating."""
    rows = []
    windows = sorted({r["window_s"] for r in ac["rows"] if r["head"] == "paper"})
    n_probes = len({r["probe"] for r in ac["rows"]})
    for w in windows:
        sel = [r for r in ac["rows"] if r["head"] == "paper" and r["window_s"] == w]
        ok = [r for r in sel if r.get("e") is not None and r.get("u_e") is not None]
        cov = [abs(r["e"] - r["e_true"]) <= 1.96 * r["u_e"] for r in ok]
        rows.append(dict(probe="paper", board=BOARDS["precision"],
                         touch=f"{n_probes} drawn as-built probes, calibrated, hand touches, {w:g} s; "
                               f"95 % interval holds e on {100 * sum(cov) / max(1, len(cov)):.0f} %",
                         answered=f"{len(ok)}/{len(sel)}", e=_rel_stats(ok, "err"), k="prior", alpha="prior",
                         kalpha="prior given e", source="asbuilt_calibrated_bench.py"))
    touches = [r for p in small["per_probe"] for r in p["rows"] if r.get("calibrated")]
    n_small = len(small["per_probe"])
    for heat in sorted({r["heat_s"] for r in touches}):
        sel = [r for r in touches if r["heat_s"] == heat]
        ok = [r for r in sel if r.get("err_e") is not None]
        cov = [bool(r.get("cov_e")) for r in ok]
        det = sum(1 for r in ok if "k" in (r.get("determined") or []))
        rows.append(dict(probe="small-heater", board=BOARDS["precision"],
                         touch=f"{n_small} drawn as-built probes, calibrated, hand touches, {heat:g} s; "
                               f"95 % interval holds e on {100 * sum(cov) / max(1, len(cov)):.0f} %",
                         answered=f"{len(ok)}/{len(sel)}", e=_rel_stats(ok, "err_e"), k=_rel_stats(ok, "err_k"),
                         alpha=_rel_stats(ok, "err_alpha"), kalpha=f"measured on {100 * det / max(1, len(ok)):.0f} %",
                         source="asbuilt_small_bench.py"))
    return rows


def short_window_table(ac: dict) -> str:
    """The paper probe's calibrated hand touches per class of solid: median |error| (attainable u) per window."""
    summ = ac["summary"]["paper"]["windows"]
    windows = sorted(summ, key=float)
    classes = sorted({c for w in windows for c in summ[w]["classes"]})
    # The last columns: the attainable u with the calibration's parts added (its covariance and model-form
    # floor, as the calibrated chain states them): what a touch answered through that calibration can reach.
    L = ["| class | " + " | ".join(f"{float(w):g} s: error (attainable u)" for w in windows) + " | "
         + " | ".join(f"{float(w):g} s: attainable with calibration" for w in windows) + " |",
         "|---|" + "---|" * (2 * len(windows))]
    for c in classes:
        cells, with_cal = [], []
        for w in windows:
            s = summ[w]["classes"].get(c, {})
            med, att = s.get("median_abs_err"), s.get("median_attainable_u_rel")
            cells.append("no answer" if med is None else f"{_pct(med)} ({_pct(att)})" if att is not None else _pct(med))
            awc = s.get("median_attainable_with_calibration_u_rel")
            with_cal.append("–" if awc is None else _pct(awc))
        L.append(f"| {c} | " + " | ".join(cells + with_cal) + " |")
    return "\n".join(L)


def table() -> str:
    """The README's accuracy table (Markdown) with the line that says where it comes from."""
    rows = paper_ideal_rows(_load("estimation"))
    rows += paper_real_rows(_load("calibration"), "precision")
    rows += paper_real_rows(_load("calibration_reference"), "reference", chains=("calibrated",))
    rows += small_heater_rows(_load("small_probe"))
    rows += small_heater_rows(_load("small_probe_reference"), contacts=("5s",))
    rows += asbuilt_rows(_load("asbuilt"))
    ac = _load("asbuilt_calibrated")
    rows += calibrated_asbuilt_rows(ac, _load("asbuilt_small"))
    L = ["| probe | board | touch | answered | e | k | α | k and α | from |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        L.append(f"| {r['probe']} | {r['board']} | {r['touch']} | {r['answered']} | {_fmt(r['e'])} | {_fmt(r['k'])} "
                 f"| {_fmt(r['alpha'])} | {r['kalpha']} | `bench/{r['source']}` |")
    L += ["", "Cells: the |relative error| of the answered touches, median [90th percentile]; \"prior\": k and α from the "
          "library prior given e (as in the ideal-contact rows). Built from `bench/results/*.json` by "
          "`python bench/accuracy_bench.py --update-readme`; the full tables are in docs/results.md. "
          "Read the rows by their world: the ideal-contact rows are the estimator's own model, the paper probe's "
          "real-contact rows as-built probes drawn by the calibration bench's own scheme (contact resistance, object "
          "off the probe's temperature), and the small heater's rows a "
          "world that read its sensor as the estimator's equal-area disk; the last two rows are probes drawn from "
          "realistic tolerances that nothing in the device shares, uncalibrated -- what a calibration has to "
          "identify (ISSUE #34), and the rows after them those probes calibrated by the walk-through and touched by "
          "hand (R_c up to 1e-4 m²K/W, the object up to 3 K off the probe, contact 0.5-3 s before heating).",
          "", "The paper probe's calibrated hand touches by class of solid and heating time: median |error| of e "
          "(in brackets the attainable u: the Fisher limit of that touch alone from `thermotouch design`, R_c and "
          "the object's temperature unknown, at the sample rate and one sample's noise the simulated touches carry "
          "(`_asbuilt_touches.sensor_noise`); the last columns add the calibration's "
          "own u -- its covariance and model-form floor as the calibrated chain states them -- which no touch "
          "through that calibration can beat; \"no answer\": the chain gave none):", "", short_window_table(ac)]
    return "\n".join(L)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--update-readme", action="store_true", help="write the table into README.md's accuracy block")
    args = ap.parse_args()
    text = table()
    print(text)
    if args.update_readme:
        print(f"updated {update_readme('accuracy', text)}")


if __name__ == "__main__":
    main()
