"""``thermotouch``: the user's command line.

Every error a user can meet prints one line on stderr and exits non-zero
(2 for bad arguments or input, 1 for device or runtime failures); no
tracebacks.
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np


class CliError(Exception):
    """An error to report to the user as one line, with an exit code."""

    def __init__(self, message: str, code: int = 2) -> None:
        super().__init__(message)
        self.code = code


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, exit 2, no usage dump
        raise CliError(f"{self.prog}: {message}", 2)


def _float(name):
    def conv(text):
        try:
            return float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a number, got {text!r}") from None
    return conv


# --- model ---------------------------------------------------------------------

def _add_model(sub):
    p = sub.add_parser("model", help="probe response calculator (forward model)")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--material", help="library material name")
    src.add_argument("--k", type=_float("--k"), help="conductivity, W/m/K (with --rho and --c)")
    p.add_argument("--rho", type=_float("--rho"), help="density, kg/m^3")
    p.add_argument("--c", type=_float("--c"), help="specific heat, J/kg/K")
    p.add_argument("--qv", type=_float("--qv"), default=7.7e7, help="heater power density, W/m^3 (default 7.7e7)")
    p.add_argument("--duration", type=_float("--duration"), default=1.95, help="record length, s (default 1.95)")
    p.add_argument("--dt", type=_float("--dt"), default=0.01, help="output spacing, s (default 0.01)")
    p.add_argument("--thickness", type=_float("--thickness"), default=0.04, help="object thickness, m (default 0.04)")
    p.add_argument("--back", choices=("fixed", "insulated", "infinite"), default="fixed",
                   help="back boundary (default fixed: held at T0, the paper's)")
    p.add_argument("--scheme", choices=("paper", "default", "explicit", "exact"), default="default")
    p.add_argument("--stack", choices=("0.42", "0.40"), default="0.42",
                   help="interface depth below the top, mm (default 0.42: 20 um heater on 0.4 mm sensing layer)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_model)


def _solid_from_args(args):
    from edge.solids import Solid

    if args.material is not None:
        from host.materials import load_materials

        lib = load_materials()
        try:
            m = lib.get(args.material)
        except KeyError as exc:
            raise CliError(f"thermotouch model: {exc.args[0]}") from None
        return Solid(m.k_W_mK, m.rho_kg_m3, m.c_J_kgK), m.name
    if args.rho is None or args.c is None:
        raise CliError("thermotouch model: --k needs --rho and --c")
    try:
        return Solid(args.k, args.rho, args.c), None
    except ValueError as exc:
        raise CliError(f"thermotouch model: {exc}") from None


def cmd_model(args) -> int:
    from edge.forward import simulate
    from edge.solids import STACKS

    solid, name = _solid_from_args(args)
    try:
        r = simulate(
            solid, args.qv, args.duration, dt_s=args.dt,
            thickness_m=None if args.back == "infinite" else args.thickness, back=args.back,
            scheme=args.scheme, stack=STACKS[args.stack],
        )
    except ValueError as exc:
        raise CliError(f"thermotouch model: {exc}") from None
    inputs = {
        "material": name, "k_W_mK": solid.k_W_mK, "rho_kg_m3": solid.rho_kg_m3, "c_J_kgK": solid.c_J_kgK,
        "q_v_W_m3": args.qv, "duration_s": args.duration, "dt_s": args.dt,
        "thickness_m": None if args.back == "infinite" else args.thickness, "back": args.back,
        "scheme": args.scheme, "stack_interface_mm": float(args.stack),
    }
    if args.json:
        out = dict(inputs)
        out.update(
            effusivity_W_s05_m2K=solid.effusivity_W_s05_m2K, alpha_m2_s=solid.alpha_m2_s,
            t_s=r.t_s.tolist(), T_f_K=r.T_f_K.tolist(), q_f_W_m2=r.q_f_W_m2.tolist(),
        )
        print(json.dumps(out))
        return 0
    label = name or f"k={solid.k_W_mK:g} W/m/K, rho={solid.rho_kg_m3:g} kg/m^3, c={solid.c_J_kgK:g} J/kg/K"
    print(f"{label}: e = {solid.effusivity_W_s05_m2K:.4g} W s^0.5/m^2/K, alpha = {solid.alpha_m2_s:.4g} m^2/s")
    print(f"q_v = {args.qv:.4g} W/m^3, {args.back} back"
          + ("" if args.back == "infinite" else f" at {args.thickness * 1e3:g} mm")
          + f", scheme {args.scheme}, {r.n_nodes} nodes")
    print(f"{'t (s)':>8} {'T_f (K)':>12} {'q_f (W/m^2)':>14}")
    idx = np.unique(np.linspace(0, r.t_s.size - 1, 11).round().astype(int))
    for i in idx:
        print(f"{r.t_s[i]:8.3f} {r.T_f_K[i]:12.5g} {r.q_f_W_m2[i]:14.5g}")
    return 0


# --- entry point -----------------------------------------------------------------

_ADDERS = [_add_model]


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="thermotouch", description="ThermoTouch contact thermal-property probe")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for add in _ADDERS:
        add(sub)
    return parser


def main(argv=None) -> int:
    try:
        args = build_parser().parse_args(argv)
        return args.func(args)
    except CliError as exc:
        print(str(exc), file=sys.stderr)
        return exc.code
    except KeyboardInterrupt:
        print("thermotouch: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into head & co.
        sys.stderr.close()
        return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
