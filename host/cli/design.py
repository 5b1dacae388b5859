"""``thermotouch design``: attainable u(e), u(k), u(alpha) of one touch for a heater radius, a time and a material.

The numbers are noise-only Cramer-Rao bounds from the axisymmetric model's
Fisher information (:func:`edge.estimation.design.attainable`): k, alpha and
the heater power unknown, no prior (``--hand``: the contact resistance and the
object's temperature too); white noise of ``--noise-T`` /
``--noise-q`` on every ``--dt`` sample.  The probe is the small-heater one
(same layers and sensors) with the heater radius replaced at the same areal
power (the heater's temperature limit, not its total power, is what a design
must respect); 32 mm is the paper's heater (equal-area disk of 55 x 60 mm).
"""

from __future__ import annotations

import argparse
import math

from edge.hw.chips import BOARDS
from host.cli.args import bounded_float, positive_float
from host.cli.errors import CliError
from host.cli.report import dumps

#: The ``--table`` grid: heater radii (mm), contact times (s), one material per class.
TABLE_RADII_MM = (5.0, 10.0, 32.0)
TABLE_TIMES_S = (1.0, 2.0, 5.0)
TABLE_MATERIALS = ("pmma", "tempered_glass", "aisi_304", "aluminium")
#: Above this relative u a quantity is not determined by the touch (the estimator's threshold).
DETERMINED_U_REL = 0.30
#: Smallest number of samples a design record must have.
MIN_SAMPLES = 5


def add_parser(sub, parents):
    p = sub.add_parser("design", help="attainable u(e), u(k), u(alpha) of one touch (Fisher information)",
                       parents=parents)
    radius = bounded_float(0.5, 100.0)
    p.add_argument("--heater-radius-mm", type=radius, dest="heater_radius", default=None, metavar="MM",
                   help="heater disk radius, mm (0.5 to 100; 32 = the paper's heater)")
    # The old spelling (the unit was not in the name): kept for one release, not shown.
    p.add_argument("--heater-radius", type=radius, dest="heater_radius", default=argparse.SUPPRESS,
                   help=argparse.SUPPRESS)
    p.add_argument("--time", type=bounded_float(0.0, 30.0, lo_open=True), default=None, metavar="S",
                   help="contact time, s (at most 30)")
    p.add_argument("--material", default=None, metavar="NAME", help="library material name, e.g. pmma")
    p.add_argument("--table", action="store_true",
                   help=f"the grid: radii {', '.join(f'{r:g}' for r in TABLE_RADII_MM)} mm x times "
                        f"{', '.join(f'{t:g}' for t in TABLE_TIMES_S)} s x {', '.join(TABLE_MATERIALS)}")
    p.add_argument("--board", choices=sorted(BOARDS), default="precision",
                   help="the board whose noise and sample interval the bound takes (default precision); "
                        "--noise-T, --noise-q and --dt override it")
    p.add_argument("--noise-T", type=positive_float, default=None, metavar="K",
                   help="thermocouple noise per sample, K (default: the board's)")
    p.add_argument("--noise-q", type=positive_float, default=None, metavar="W_M2",
                   help="flux-sensor noise per sample, W/m^2 (default: the board's)")
    p.add_argument("--dt", type=bounded_float(1e-3, 1.0), default=None, metavar="S",
                   help="sample interval, s (default: the board's)")
    p.add_argument("--hand", action="store_true",
                   help="a hand touch: the contact resistance and the object's temperature are unknowns too "
                        "(ISSUE #34: what a touch can attain when it does not know them)")
    p.add_argument("--contact-resistance", type=bounded_float(0.0, 1e-2), default=3e-5, metavar="M2K_W",
                   help="with --hand: the touch's contact resistance, m^2K/W (default 3e-5)")
    p.add_argument("--lead", type=bounded_float(0.0, 30.0), default=1.0, metavar="S",
                   help="with --hand: contact before heating, s (default 1)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def _pct(u: float | None) -> str:
    if u is None or not math.isfinite(u) or u >= 1.0:
        return "> 100 %"
    return f"{100 * u:.2g} %" if u < 0.1 else f"{100 * u:.0f} %"


def _material(name: str):
    from edge.physics.materials import load_materials  # noqa: PLC0415

    try:
        return load_materials().get(name)
    except KeyError as exc:
        raise CliError(f"--material: {exc.args[0]}") from None


def compute(material: str, radius_mm: float, time_s: float, *, noise_T_K: float,
            noise_q_W_m2: float, dt_s: float, model=None, hand: bool = False,
            contact_resistance_m2K_W: float = 3e-5, lead_s: float = 1.0) -> dict:
    """One design point as a JSON-able dict (see the module docstring).

    ``hand``: R_c (at ``contact_resistance_m2K_W``) and the object's temperature (contact ``lead_s``
    before heating) are unknowns as well.
    """
    from edge.estimation.design import attainable  # noqa: PLC0415

    m = _material(material)
    extra = ({"fit_contact": True, "contact_resistance_m2K_W": contact_resistance_m2K_W,
              "fit_object_temperature": True, "contact_lead_s": lead_s} if hand else {})
    d = attainable(m.solid, time_s, heater_radius_m=radius_mm * 1e-3, dt_s=dt_s, sigma_T_K=noise_T_K,
                   sigma_q_W_m2=noise_q_W_m2, model=model, **extra).to_dict()
    out = {"material": m.name, "heater_radius_mm": radius_mm, "time_s": time_s, **d,
           "noise_T_K": noise_T_K, "noise_q_W_m2": noise_q_W_m2, "dt_s": dt_s,
           "hand": ({"contact_resistance_m2K_W": contact_resistance_m2K_W, "lead_s": lead_s} if hand else None)}
    out["determined"] = [q for q, key in (("e", "u_rel_effusivity"), ("k", "u_rel_k"), ("alpha", "u_rel_alpha"))
                         if d[key] is not None and d[key] < DETERMINED_U_REL]
    return out


def table(*, noise_T_K: float, noise_q_W_m2: float, dt_s: float, **hand) -> list[dict]:
    """Every point of the ``--table`` grid (one model per radius and time, shared by the materials)."""
    import numpy as np  # noqa: PLC0415

    from edge.physics.axisym import AxisymModel  # noqa: PLC0415
    from edge.physics.geometry import PROBES  # noqa: PLC0415

    rows = []
    for r in TABLE_RADII_MM:
        g = PROBES["small-heater"].with_heater_radius(r * 1e-3)
        for t_end in TABLE_TIMES_S:
            t = dt_s * np.arange(1, int(math.floor(t_end / dt_s + 1e-9)) + 1)
            model = AxisymModel(g, t)  # its probe part is the costly setup: once for the four materials
            for name in TABLE_MATERIALS:
                rows.append(compute(name, r, t_end, noise_T_K=noise_T_K, noise_q_W_m2=noise_q_W_m2, dt_s=dt_s,
                                    model=model, **hand))
    return rows


def table_lines(rows: list[dict]) -> list[str]:
    """Markdown: one row per material and radius, one column per time, cells u(e) / u(k) / u(alpha)."""
    times = sorted({r["time_s"] for r in rows})
    head = "| material | heater radius (mm) | " + " | ".join(f"{t:g} s: u(e) / u(k) / u(α)" for t in times) + " |"
    lines = [head, "|---|---|" + "---|" * len(times)]
    keyed = {(r["material"], r["heater_radius_mm"], r["time_s"]): r for r in rows}
    for name in dict.fromkeys(r["material"] for r in rows):
        for rad in dict.fromkeys(r["heater_radius_mm"] for r in rows):
            cells = []
            for t in times:
                r = keyed[(name, rad, t)]
                cells.append(" / ".join(_pct(r[k]) for k in ("u_rel_effusivity", "u_rel_k", "u_rel_alpha")))
            lines.append(f"| {name} | {rad:g} | " + " | ".join(cells) + " |")
    return lines


def noise_of(args) -> tuple[float, float, float]:
    """(noise_T_K, noise_q_W_m2, dt_s): the board's one-sample noise and interval, each overridden when given."""
    from host.objects import board_noise  # noqa: PLC0415

    board = board_noise(args.board)
    given = (args.noise_T, args.noise_q, args.dt)
    return tuple(float(b if g is None else g) for g, b in zip(given, board))


def run(args) -> int:
    # The board is named in the answer only when its noise is what was used.
    board = args.board if (args.noise_T, args.noise_q, args.dt) == (None, None, None) else None
    noise_T, noise_q, dt = noise_of(args)   # the parsed arguments stay as the user gave them
    one = (args.heater_radius, args.time, args.material)
    if args.table:
        if any(v is not None for v in one):
            raise CliError("--table computes its own grid; drop --heater-radius-mm, --time and --material")
    elif any(v is None for v in one):
        raise CliError("give --heater-radius-mm MM, --time S and --material NAME (or --table)")
    if not args.table and args.time / dt < MIN_SAMPLES:
        raise CliError(f"--time {args.time:g} s holds fewer than {MIN_SAMPLES} samples of --dt {dt:g} s")
    if args.table and min(TABLE_TIMES_S) / dt < MIN_SAMPLES:
        raise CliError(f"--dt {dt:g} s leaves fewer than {MIN_SAMPLES} samples in a {min(TABLE_TIMES_S):g}-s touch")
    kw = {"noise_T_K": noise_T, "noise_q_W_m2": noise_q, "dt_s": dt}
    if args.hand:
        kw.update(hand=True, contact_resistance_m2K_W=args.contact_resistance, lead_s=args.lead)
    if args.table:
        rows = table(**kw)
        if args.json:
            print(dumps({"board": board, "rows": rows}))
        else:
            print("\n".join(table_lines(rows)))
        return 0
    d = {**compute(args.material, args.heater_radius, args.time, **kw), "board": board}
    if args.json:
        print(dumps(d))
        return 0
    print(f"{d['material']}, heater radius {d['heater_radius_mm']:g} mm ({d['power_W']:.3g} W), "
          f"{d['contact_time_s']:g} s touch; noise {noise_T:.2g} K / {noise_q:.2g} W/m^2 every {dt:g} s"
          + (f" ({board} board)" if board else ""))
    if args.hand:
        print(f"hand touch: R_c ({args.contact_resistance:g} m^2K/W) and the object's temperature unknown, contact "
              f"{args.lead:g} s before heating")
    for label, key, q in (("u(e)", "u_rel_effusivity", "e"), ("u(k)", "u_rel_k", "k"),
                          ("u(alpha)", "u_rel_alpha", "alpha")):
        verdict = "determined" if q in d["determined"] else "not determined (the library prior answers)"
        print(f"{label:9s}{_pct(d[key]):>9s}  {verdict}")
    corr = d["corr_k_alpha"]
    print(f"corr(k, alpha) {'n/a' if corr is None else f'{corr:+.2f}'}")
    return 0
