"""``thermotouch model``: the probe response calculator (forward model)."""

from __future__ import annotations

import argparse

from edge.physics.probe import HEATER_AREA_m2, HEATER_VOLUME_m3

from host.cli.args import bounded_float, positive_float
from host.cli.errors import CliError
from host.cli.report import dumps, model_json, model_lines

#: The paper's heater power density, W/m^3 (the calculator's default drive).
PAPER_QV_W_M3 = 7.7e7
#: Longest record the calculator computes, s (the probe's touches last seconds).
MAX_DURATION_S = 3600.0
#: Most output samples (duration / dt): bounds memory and time (a 1e6 s record at 10 ms would need 28 GiB).
MAX_SAMPLES = 100_000


def add_parser(sub, parents):
    p = sub.add_parser("model", help="probe response calculator (forward model)", parents=parents)
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--material", help="library material name")
    src.add_argument("--k", type=positive_float, help="conductivity, W/m/K (with --rho and --c)")
    p.add_argument("--rho", type=positive_float, help="density, kg/m^3")
    p.add_argument("--c", type=positive_float, help="specific heat, J/kg/K")
    power = p.add_mutually_exclusive_group()
    power.add_argument("--power", type=positive_float, default=None,
                       help=f"heater power, W, over the paper probe's {HEATER_AREA_m2 * 1e6:g} mm^2 heater "
                            f"(default {PAPER_QV_W_M3 * HEATER_VOLUME_m3:.4g}: the paper's {PAPER_QV_W_M3:g} W/m^3)")
    power.add_argument("--voltage", type=positive_float, default=None,
                       help="heater supply voltage, V, across the device's default heater resistance "
                            "(heater.resistance_ohm)")
    # The old spelling, in the forward model's own unit (W/m^3): kept for one release, not shown.
    power.add_argument("--qv", type=positive_float, default=None, help=argparse.SUPPRESS)
    time = bounded_float(0.0, MAX_DURATION_S, lo_open=True)
    p.add_argument("--time", type=time, default=1.95,
                   help=f"contact (heating) time, s: the record's length (default 1.95, at most {MAX_DURATION_S:g})")
    p.add_argument("--duration", type=time, dest="time", default=argparse.SUPPRESS, help=argparse.SUPPRESS)
    p.add_argument("--dt", type=positive_float, default=0.01,
                   help=f"output spacing, s (default 0.01; at most {MAX_SAMPLES} samples)")
    p.add_argument("--thickness", type=positive_float, default=0.04, help="object thickness, m (default 0.04)")
    p.add_argument("--back", choices=("fixed", "insulated", "infinite"), default="fixed",
                   help="back boundary (default fixed: held at T0, the paper's)")
    p.add_argument("--scheme", choices=("paper", "default", "explicit", "exact"), default="default")
    p.add_argument("--stack", choices=("0.42", "0.40"), default="0.42",
                   help="interface depth below the top, mm (default 0.42: 20 um heater on 0.4 mm sensing layer)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def _solid(args):
    from edge.physics.solids import Solid  # noqa: PLC0415

    if args.material is not None:
        from edge.physics.materials import load_materials  # noqa: PLC0415

        try:
            m = load_materials().get(args.material)
        except KeyError as exc:
            raise CliError(f"--material: {exc.args[0]}") from None
        return Solid(m.k_W_mK, m.rho_kg_m3, m.c_J_kgK), m.name
    if args.rho is None or args.c is None:
        raise CliError("--k needs --rho and --c")
    try:
        return Solid(args.k, args.rho, args.c), None
    except ValueError as exc:
        raise CliError(str(exc)) from None


def _q_v(args) -> tuple[float, float]:
    """(q_v W/m^3, power W) of the drive given: --power, --voltage or the hidden --qv (default: the paper's)."""
    from edge.physics.probe import DEFAULT_STACK  # noqa: PLC0415

    if args.power is not None:
        return DEFAULT_STACK.q_v_from_power(args.power), args.power
    if args.voltage is not None:
        from edge.service.config import Config  # noqa: PLC0415

        q_v = DEFAULT_STACK.q_v_from_voltage(args.voltage, Config().heater.resistance_ohm)
        return q_v, q_v * HEATER_VOLUME_m3
    q_v = PAPER_QV_W_M3 if args.qv is None else args.qv
    return q_v, q_v * HEATER_VOLUME_m3


def run(args) -> int:
    if args.material is not None and (args.rho is not None or args.c is not None):
        raise CliError("--rho and --c go with --k, not with --material")
    if args.dt > args.time:
        raise CliError(f"--dt {args.dt:g} is longer than --time {args.time:g}")
    if args.time / args.dt > MAX_SAMPLES:
        raise CliError(f"--time / --dt gives {args.time / args.dt:.3g} samples, more than {MAX_SAMPLES} "
                       "(raise --dt or shorten --time)")
    from edge.physics.forward import simulate  # noqa: PLC0415
    from edge.physics.probe import STACKS  # noqa: PLC0415

    solid, name = _solid(args)
    q_v, power_W = _q_v(args)
    thickness = None if args.back == "infinite" else args.thickness
    try:
        r = simulate(solid, q_v, args.time, dt_s=args.dt, thickness_m=thickness, back=args.back,
                     scheme=args.scheme, stack=STACKS[args.stack])
    except ValueError as exc:
        raise CliError(str(exc)) from None
    inputs = {
        "material": name, "k_W_mK": solid.k_W_mK, "rho_kg_m3": solid.rho_kg_m3, "c_J_kgK": solid.c_J_kgK,
        "q_v_W_m3": q_v, "power_W": power_W, "duration_s": args.time, "dt_s": args.dt, "thickness_m": thickness,
        "back": args.back, "scheme": args.scheme, "stack_interface_mm": float(args.stack),
    }
    if args.json:
        print(dumps(model_json(inputs, solid, r)))
    else:
        print("\n".join(model_lines(name, solid, inputs, r)))
    return 0
