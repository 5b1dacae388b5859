"""Text and JSON forms of results: what the verbs print, apart from how their arguments are handled."""

from __future__ import annotations

import json
import math
from typing import Any, Iterable

import numpy as np

__all__ = [
    "pm", "result_lines", "print_result", "measure_json", "model_json", "model_lines", "evaluate_lines",
    "info_lines", "HISTORY_CSV_COLUMNS", "history_row", "csv_cell", "history_lines", "dumps",
]


def dumps(obj: Any) -> str:
    """One line of JSON."""
    return json.dumps(obj)


def pm(v: float | None, u: float | None, unit: str, scale: float = 1.0) -> str:
    """``v ± u unit`` rounded to two significant digits of ``u``."""
    if v is None:
        return "n/a"
    v = v * scale
    if not u or not u > 0:
        return f"{v:.4g} {unit}"
    u = u * scale
    decimals = 1 - int(math.floor(math.log10(u)))
    if decimals >= 0:
        return f"{v:.{decimals}f} ± {u:.{decimals}f} {unit}"
    q = 10.0 ** (-decimals)
    return f"{round(v / q) * q:.0f} ± {round(u / q) * q:.0f} {unit}"


#: The one ± convention, stated once per output that prints uncertainties.
UNCERTAINTY_NOTE = "± is one standard uncertainty (coverage factor k = 1, about 68 %)"


def result_lines(d: dict) -> list[str]:
    """Human-readable estimate (rounded to its uncertainty)."""
    lines = [
        f"effusivity   {pm(d['effusivity_W_s05_m2K'], d['effusivity_W_s05_m2K_u'], 'W s^0.5/m^2/K')}",
        f"conductivity {pm(d['k_W_mK'], d['k_W_mK_u'], 'W/m/K')}",
        f"diffusivity  {pm(d['alpha_m2_s'], d['alpha_m2_s_u'], 'mm^2/s', 1e6)}",
    ]
    if d["material"]:
        lines.append(f"material     {d['material']} (confidence {d['material_confidence'] * 100:.0f} %)")
    if d.get("object") is not None and d.get("object_posterior") is not None:   # named, or unknown by the test
        cands = ", ".join(f"{c['name']} {c['posterior']:.2f}" for c in d.get("candidates") or [])
        lines.append(f"object       {d['object']} (posterior {d['object_posterior']:.2f}; class {d['class']} "
                     f"{d['class_posterior']:.2f}; set {d.get('object_set')}; candidates {cands})")
    if d.get("probe"):  # the axisymmetric estimate says what the touch itself determined
        corr = d.get("corr_k_alpha")
        lines.append(f"probe {d['probe']}: determined {', '.join(d.get('determined') or []) or 'nothing'}; "
                     f"from the prior {', '.join(d.get('from_prior') or []) or 'nothing'}"
                     + ("" if corr is None else f"; corr(k, alpha) {corr:+.2f}"))
    if d.get("prior_reason"):
        lines.append(f"prior: {d['prior_reason']}")
    lines.append(f"method {d['method']}, model {(d.get('model_sha256') or '')[:12]}, "
                 f"flags: {', '.join(d['flags']) or 'none'}")
    lines.append(UNCERTAINTY_NOTE)
    return lines


def print_result(d: dict) -> None:
    print("\n".join(result_lines(d)))


def measure_json(rec: dict) -> dict:
    """The device's MEASURE record as the user's result: estimate, flags (device's and estimator's), id, power.

    It carries the object fields ``estimate --json`` gives (object, class,
    posteriors, candidates: :data:`edge.recognition.RESULT_KEYS`) as
    the device named them among its active object set; a device whose
    records lack them (older firmware) gives None and no candidates.
    """
    from edge.recognition import RESULT_KEYS  # noqa: PLC0415

    out = dict(rec["result"])
    for key in RESULT_KEYS:
        out.setdefault(key, [] if key == "candidates" else None)
    if out["candidates"] and not isinstance(out["candidates"][0], dict):
        out["candidates"] = []  # an older record's library ranking ([name, p] pairs), not the object's
    out["flags"] = list(dict.fromkeys(list(rec.get("flags") or []) + list(out.get("flags") or [])))
    out.update(measurement_id=rec["measurement_id"], power_W=rec.get("power_W"),
               contact_time_s=rec.get("contact_time_s"))
    return out


def model_json(inputs: dict, solid: Any, r: Any) -> dict:
    out = dict(inputs)
    out.update(
        effusivity_W_s05_m2K=solid.effusivity_W_s05_m2K, alpha_m2_s=solid.alpha_m2_s,
        t_s=r.t_s.tolist(), T_f_K=r.T_f_K.tolist(), q_f_W_m2=r.q_f_W_m2.tolist(),
    )
    return out


def model_lines(name: str | None, solid: Any, inputs: dict, r: Any) -> list[str]:
    label = name or f"k={solid.k_W_mK:g} W/m/K, rho={solid.rho_kg_m3:g} kg/m^3, c={solid.c_J_kgK:g} J/kg/K"
    back, thickness = inputs["back"], inputs["thickness_m"]
    lines = [
        f"{label}: e = {solid.effusivity_W_s05_m2K:.4g} W s^0.5/m^2/K, alpha = {solid.alpha_m2_s:.4g} m^2/s",
        f"q_v = {inputs['q_v_W_m3']:.4g} W/m^3, {back} back"
        + ("" if thickness is None else f" at {thickness * 1e3:g} mm")
        + f", scheme {inputs['scheme']}, {r.n_nodes} nodes",
        f"{'t (s)':>8} {'T_f (K)':>12} {'q_f (W/m^2)':>14}",
    ]
    idx = np.unique(np.linspace(0, r.t_s.size - 1, 11).round().astype(int))
    for i in idx:
        lines.append(f"{r.t_s[i]:8.3f} {r.T_f_K[i]:12.5g} {r.q_f_W_m2[i]:14.5g}")
    return lines


def evaluate_lines(rows: list[dict], ident: dict, sha256: str, instrument: str) -> list[str]:
    def f(x):
        return "   -   " if x is None else f"{x * 100:+6.1f}%"

    lines = [f"bundle {sha256[:12]}, instrument {instrument}; mean errors over 3 noisy touches",
             f"{'sample':16} {'V':>4} {'method':8} {'e err':>7} {'k err':>7} {'alpha err':>9}"]
    for r in rows:
        lines.append(f"{r['sample']:16} {r['voltage_V']:4.0f} {r['method']:8} {f(r['e_err']):>7} {f(r['k_err']):>7} "
                     f"{f(r['alpha_err']):>9}")
    lines.append(f"identification: top-1 {ident['top1'] * 100:.1f} % of {ident['touches']} touches; "
                 f"{(ident['top1_resolvable'] or 0) * 100:.1f} % where effusivities differ by > 2 u")
    lines.append("by class: " + ", ".join(f"{c} {v * 100:.0f} %" for c, v in ident["by_class"].items()))
    return lines


def info_lines(port: str, info: dict, status: dict) -> list[str]:
    return [
        f"port       {port}",
    ] + ([f"device     {info['device_id']}"] if "device_id" in info else []) + [
        f"board      {info['board']}, firmware {info['firmware_version']}, protocol {info['protocol_version']}",
        f"model      {info.get('model_version')} (sha256 {info.get('model_sha256')}, "
        f"{info.get('model_source') or 'unknown source'})",
        f"state      {status['state']}, {status.get('history_total', 0)} measurement(s) stored",
    ] + ([f"objects    {info['object_set']} (names each measurement's object; thermotouch objects list)"]
         if info.get("object_set") else []) + (
        [] if "calibrated" not in info else  # older firmware says nothing about calibration
        [f"calibration {info['calibration_sha256'][:12]} (thermotouch calibrate --show)" if info["calibrated"]
         else "calibration none: measurements are flagged 'uncalibrated' (thermotouch calibrate)"])


HISTORY_CSV_COLUMNS = (
    "measurement_id", "created_utc", "started_utc", "status", "reason", "power_W", "contact_time_s",
    "heater_on_s", "T0_C", "effusivity_W_s05_m2K", "effusivity_W_s05_m2K_u", "k_W_mK", "k_W_mK_u",
    "alpha_m2_s", "alpha_m2_s_u", "material", "material_confidence", "object_set", "object", "object_posterior",
    "class", "class_posterior", "method", "model_sha256", "calibration_sha256", "flags",
)

# A cell a spreadsheet would run as a formula (=, +, -, @, and tab/CR that some read as the same):
# text from outside (object names, materials) is quoted with a leading apostrophe; numbers are not text.
_FORMULA_START = ("=", "+", "-", "@", "\t", "\r")


def csv_cell(v):
    """A history-export cell that a spreadsheet shows as text, never runs (ISSUE #35 §10)."""
    if isinstance(v, str) and v.startswith(_FORMULA_START):
        return "'" + v
    return v


def history_row(item: dict) -> dict:
    r = item.get("result") or {}
    row = {k: item.get(k) for k in HISTORY_CSV_COLUMNS}
    for k in ("effusivity_W_s05_m2K", "effusivity_W_s05_m2K_u", "k_W_mK", "k_W_mK_u", "alpha_m2_s",
              "alpha_m2_s_u", "material", "material_confidence", "object_set", "object", "object_posterior",
              "class", "class_posterior", "method"):
        row[k] = r.get(k)  # the object fields are None in records stored before object sets
    row["model_sha256"] = item.get("model_sha256") or r.get("model_sha256")
    row["calibration_sha256"] = r.get("calibration_sha256")
    row["flags"] = " ".join(item.get("flags") or [])
    return row


def history_lines(items: Iterable[dict], export: str | None) -> list[str]:
    items = list(items)
    lines = [f"{len(items)} measurement(s)" + (f"; exported to {export}" if export else "")]
    if items:
        lines.append(f"{'id':>5} {'started (UTC)':20} {'status':8} {'e':>9} {'k W/m/K':>9} {'α mm²/s':>9} "
                     f"{'material':24} flags")

    def f(v, s=1.0):
        return "-" if v is None else f"{v * s:.4g}"

    for it in items:
        r = history_row(it)
        lines.append(f"{r['measurement_id']:>5} {str(r['started_utc'] or '')[:19]:20} {r['status']:8} "
                     f"{f(r['effusivity_W_s05_m2K']):>9} {f(r['k_W_mK']):>9} {f(r['alpha_m2_s'], 1e6):>9} "
                     f"{str(r['material'] or '-'):24} {r['flags'] or '-'}")
    return lines
