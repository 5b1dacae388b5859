"""The calibration certificate of a probe: one HTML page from the calibration JSON ``thermotouch calibrate`` writes.

It states the probe head, when the calibration was made and its identity
(sha256, the id measurements record), the reference materials with their
certified effusivities and uncertainties and how the calibrated probe then
read each of them (the relative error of every touch), the fitted sensor
chain parameters with their standard uncertainties and correlations, the
residual floor added to every measurement's u, and who issued it when.  The
calibration file is read with its own checker
(:meth:`edge.calibration.model.ProbeCalibration.from_json`).
"""

from __future__ import annotations

import math

import numpy as np

from host.lab_html import esc, figure_png, fmt, kv_table, page, pm, png_img, pyplot, table

__all__ = ["certificate_html", "certificate_parts", "certificate_blocks", "residual_plot_png", "PARAMETER_LABELS"]

#: How each calibrated parameter is shown (the words of ``thermotouch calibrate``): label, unit, display
#: scale, and how theta maps to the shown value: "exp" (theta is its logarithm), "inv_exp" (theta is the
#: logarithm of its inverse: the flux scale is nominal / true sensitivity), "lin".
PARAMETER_LABELS = {
    "ln_flux_scale": ("flux sensor sensitivity, × nominal (1 / flux_scale)", "×", 1.0, "inv_exp"),
    "ln_sensing_thickness_m": ("sensing depth", "mm", 1e3, "exp"),
    "tc_tau_s": ("thermocouple lag", "ms", 1e3, "lin"),
    "ln_sensing_k_W_mK": ("sensing layer k", "W/(m K)", 1.0, "exp"),
}


def _value_u(name: str, theta: float, u_theta: float) -> tuple[float, float]:
    """A parameter's value and standard uncertainty in its own unit (a logarithm's u is relative)."""
    how = PARAMETER_LABELS[name][3]
    if how == "lin":
        return theta, u_theta
    v = math.exp(-theta if how == "inv_exp" else theta)
    return v, v * u_theta


def residual_plot_png(cal) -> bytes:
    """Each reference touch's relative error after calibration (%), with the reference's own u and the floor."""
    plt = pyplot()
    refs = cal.references
    fig, ax = plt.subplots(figsize=(7.5, 2.8))
    for i, r in enumerate(refs):
        errs = np.asarray(r.rel_errors, dtype=float) * 100
        ax.errorbar([i] * 1, [0.0], yerr=[r.u_rel_e * 100], fmt="none", ecolor="C1", capsize=8, linewidth=2,
                    label="certified value ± u (k = 1)" if i == 0 else None)
        jitter = np.linspace(-0.15, 0.15, errs.size) if errs.size > 1 else np.zeros(errs.size)
        ax.plot(i + jitter, errs, "o", color="C0", label="touch: calibrated e / certified e − 1" if i == 0 else None)
    if cal.u_rel_floor > 0:
        ax.axhspan(-cal.u_rel_floor * 100, cal.u_rel_floor * 100, color="0.5", alpha=0.15,
                   label="± residual floor added to every u(e)")
    ax.axhline(0, color="0.3", linewidth=0.8)
    ax.set_xticks(range(len(refs)))
    ax.set_xticklabels([r.name for r in refs])
    ax.set_xlim(-0.6, len(refs) - 0.4)
    ax.set_ylabel("relative error of e (%)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    return figure_png(fig)


REFERENCE_HEADER = ["reference", "certified e (W s^0.5/(m² K))", "u (k = 1)", "touches",
                    "re-measured after calibration: e / certified − 1 (%)", "mean", "rms",
                    "against 2 u (reference and floor, k = 2)"]
PARAMETER_HEADER = ["parameter", "name", "value ± u", "unit", "relative u"]
#: The sentence on identity and coverage (HTML and PDF).
IDENTITY_NOTE = ("Measurements made with this calibration record its sha256 as calibration_sha256. "
                 "± values are standard uncertainties (coverage factor k = 1).")


def certificate_parts(cal, *, source_name: str, generated_utc: str, software_version: str,
                      issued_by: str | None = None, notes: str | None = None) -> dict:
    """The certificate's content, shared by the HTML page and the PDF: title, identity pairs, the references'
    rows, the parameters' rows, the chain pairs, the correlation table."""
    from edge.calibration.model import PARAMETERS  # noqa: PLC0415

    theta, u_theta = cal.theta, cal.u_theta
    cov = np.asarray(cal.covariance, dtype=float)
    d = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(d, d)
    par_rows = []
    for i, name in enumerate(PARAMETERS):
        label, unit, scale, _ = PARAMETER_LABELS[name]
        v, u = _value_u(name, float(theta[i]), float(u_theta[i]))
        rel = f"{u / abs(v) * 100:.2f} %" if v else "–"
        par_rows.append([label, name, pm(v, u, scale) if u > 0 else fmt(v, 5, scale), unit, rel])
    corr_rows = [[PARAMETERS[i]] + [fmt(float(corr[i, j]), 3) if np.isfinite(corr[i, j]) else "–"
                                    for j in range(len(PARAMETERS))] for i in range(len(PARAMETERS))]
    ref_rows = []
    for r in cal.references:
        errs = np.asarray(r.rel_errors, dtype=float)
        with np.errstate(over="ignore"):  # a file's absurd error is shown as inf, not warned about on stderr
            rms = math.sqrt(float(np.mean(errs ** 2))) if errs.size else None
        # a re-measured touch further than 2 u from the certified value (u: the reference's and the floor)
        u2 = 2.0 * math.hypot(r.u_rel_e, cal.u_rel_floor)
        outside = int(np.sum(np.abs(errs) > u2))
        ref_rows.append([r.name, fmt(r.e_W_s05_m2K, 5), f"{r.u_rel_e * 100:.2f} %", str(r.n_touches),
                         ", ".join(f"{x * 100:+.2f}" for x in errs) or "–",
                         f"{errs.mean() * 100:+.2f} %" if errs.size else "–",
                         f"{rms * 100:.2f} %" if rms is not None else "–",
                         f"{outside} of {errs.size} outside ±{u2 * 100:.1f} %" if outside else
                         f"all within ±{u2 * 100:.1f} %"])
    return {
        "title": f"Calibration certificate: probe {cal.probe}",
        "identity": [("probe head", cal.probe), ("calibration created (UTC)", cal.created_utc or None),
                     ("calibration identity (sha256)", cal.sha256), ("calibration file", source_name),
                     ("issued by", issued_by), ("notes", notes), ("certificate generated (UTC)", generated_utc),
                     ("software", f"thermotouch {software_version}")],
        "references": ref_rows, "parameters": par_rows,
        "chain": [("sensing layer diffusivity (m²/s, from k and the nominal ρc)", fmt(cal.chain.alpha_m2_s, 4)),
                  ("residual floor added to every u(e) (relative, k = 1)", f"{cal.u_rel_floor * 100:.2f} %")],
        "corr_header": ["", *PARAMETERS], "correlation": corr_rows,
        "footer": f"Certificate generated {generated_utc} by thermotouch {software_version} from {source_name}.",
        "residual_png": residual_plot_png(cal) if cal.references else None,
    }


def certificate_html(cal, *, source_name: str, generated_utc: str, software_version: str,
                     issued_by: str | None = None, notes: str | None = None, parts: dict | None = None) -> str:
    """The certificate page of a checked calibration (a :class:`edge.calibration.model.ProbeCalibration`).

    ``parts``: :func:`certificate_parts` when the caller made them already (the PDF uses the same).
    """
    c = parts or certificate_parts(cal, source_name=source_name, generated_utc=generated_utc,
                                   software_version=software_version, issued_by=issued_by, notes=notes)
    n_par = len(c["corr_header"]) - 1
    body = [
        f"<h1>{esc(c['title'])}</h1>",
        kv_table(c["identity"]),
        f"<p class=\"note\">{esc(IDENTITY_NOTE)}</p>",
        "<h2>Reference materials</h2>",
        table(REFERENCE_HEADER, c["references"], numeric=(1, 2, 3, 5, 6)) if c["references"]
        else "<p>No references recorded.</p>",
        png_img(c["residual_png"], "relative error of each reference touch after calibration")
        if c["residual_png"] else "",
        "<h2>Fitted sensor chain parameters</h2>",
        table(PARAMETER_HEADER, c["parameters"], numeric=(2, 4)),
        kv_table(c["chain"]),
        "<h3>Correlation of the fitted parameters</h3>",
        table(c["corr_header"], c["correlation"], numeric=tuple(range(1, n_par + 1))),
        f"<p class=\"note\">{esc(c['footer'])}</p>",
    ]
    return page(c["title"], body)


def certificate_blocks(parts: dict) -> list[tuple]:
    """The certificate as :mod:`host.lab_pdf` blocks (the HTML page's content, in its order)."""
    return [
        ("h1", parts["title"]), ("kv", parts["identity"]), ("note", IDENTITY_NOTE),
        ("h2", "Reference materials"),
        ("table", REFERENCE_HEADER, parts["references"]) if parts["references"] else ("p", "No references recorded."),
        *((("png", parts["residual_png"]),) if parts["residual_png"] else ()),
        ("h2", "Fitted sensor chain parameters"), ("table", PARAMETER_HEADER, parts["parameters"]),
        ("kv", parts["chain"]),
        ("h2", "Correlation of the fitted parameters"), ("table", parts["corr_header"], parts["correlation"]),
        ("note", parts["footer"]),
    ]
