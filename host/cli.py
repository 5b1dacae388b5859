"""``thermotouch``: the user's command line.

Every error a user can meet prints one line on stderr and exits non-zero
(2 for bad arguments or input, 1 for device or runtime failures); no
tracebacks.
"""

from __future__ import annotations

import argparse
import json
import math
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


# --- train / evaluate / estimate ----------------------------------------------------

def _load_estimator(path, method="default"):
    from edge.bundle import BundleError, load_bundle
    from edge.estimate import Estimator, pipeline_golden_check

    if path is None:
        from thermotouch_models import DEFAULT_BUNDLE

        path = DEFAULT_BUNDLE
    try:
        bundle = load_bundle(path, golden_check=pipeline_golden_check)
    except BundleError as exc:
        raise CliError(f"thermotouch: bundle {path} refused: {exc}", 2) from None
    est = Estimator.from_bundle(bundle)
    if method == "paper" and not est.has_paper:
        raise CliError(f"thermotouch: bundle {path} has no paper network", 2)
    return est, bundle


def _add_train(sub):
    p = sub.add_parser("train", help="generate the training set, train the paper network, write a bundle")
    p.add_argument("--out", required=True, help="bundle directory to create")
    p.add_argument("--quick", action="store_true", help="6 power levels, no noisy copies, fewer iterations")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--overwrite", action="store_true")
    p.set_defaults(func=cmd_train)


def cmd_train(args) -> int:
    import warnings

    from host.train import train_bundle

    try:
        from tqdm import tqdm
    except ImportError:  # pragma: no cover - tqdm is in the host extra
        tqdm = None
    bar = tqdm(total=0, desc="training set", unit="material", file=sys.stderr) if tqdm else None

    def progress(i, n):
        if bar is not None:
            bar.total = n
            bar.n = i
            bar.refresh()

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # sklearn convergence chatter; metrics tell the truth
        try:
            train_bundle(args.out, quick=args.quick, seed=args.seed, progress=progress, overwrite=args.overwrite,
                         log=lambda s: print(s, file=sys.stderr))
        except FileExistsError:
            raise CliError(f"thermotouch train: {args.out} exists (use --overwrite)") from None
        finally:
            if bar is not None:
                bar.close()
    return 0


def _add_evaluate(sub):
    p = sub.add_parser("evaluate", help="accuracy tables of a bundle on simulated measurements")
    p.add_argument("bundle", nargs="?", default=None, help="bundle directory (default: the shipped one)")
    p.add_argument("--instrument", choices=("mcp9600", "ads122c04"), default="ads122c04")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_evaluate)


def cmd_evaluate(args) -> int:
    from host.evaluate import identification, paper_cases

    est, bundle = _load_estimator(args.bundle)
    rows = paper_cases(est, args.instrument, repeats=3)
    ident = identification(est, args.instrument, touches=2)
    if args.json:
        print(json.dumps({"paper_cases": rows, "identification": ident, "model_sha256": bundle.sha256}))
        return 0
    print(f"bundle {bundle.sha256[:12]}, instrument {args.instrument}; mean errors over 3 noisy touches")
    print(f"{'sample':16} {'V':>4} {'method':8} {'e err':>7} {'k err':>7} {'alpha err':>9}")
    for r in rows:
        f = lambda x: "   -   " if x is None else f"{x * 100:+6.1f}%"
        print(f"{r['sample']:16} {r['voltage_V']:4.0f} {r['method']:8} {f(r['e_err']):>7} {f(r['k_err']):>7} "
              f"{f(r['alpha_err']):>9}")
    print(f"identification: top-1 {ident['top1'] * 100:.1f} % of {ident['touches']} touches; "
          f"{(ident['top1_resolvable'] or 0) * 100:.1f} % where effusivities differ by > 2 u")
    print("by class: " + ", ".join(f"{c} {v * 100:.0f} %" for c, v in ident["by_class"].items()))
    return 0


def _add_estimate(sub):
    p = sub.add_parser("estimate", help="e, k, alpha and the material from a recorded series")
    p.add_argument("--bundle", default=None, help="bundle directory (default: the shipped one)")
    p.add_argument("--csv", required=True, help="record: columns t_s, T_K or dT_K, q_W_m2")
    p.add_argument("--method", choices=("paper", "default"), default="default")
    p.add_argument("--thickness", type=_float("--thickness"), default=None, help="known object thickness, m")
    p.add_argument("--back", choices=("insulated", "fixed"), default="insulated",
                   help="back boundary when --thickness is given")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_estimate)


def cmd_estimate(args) -> int:
    from host.records import RecordError, read_record

    est, _ = _load_estimator(args.bundle, args.method)
    try:
        t, dT, q = read_record(args.csv)
    except RecordError as exc:
        raise CliError(f"thermotouch estimate: {exc}") from None
    try:
        r = est.estimate(t, dT, q, method=args.method, thickness_m=args.thickness,
                         back=args.back if args.thickness else "infinite")
    except ValueError as exc:
        raise CliError(f"thermotouch estimate: {exc}") from None
    d = r.to_dict()
    if args.json:
        print(json.dumps(d))
        return 0
    print_result(d)
    return 0


def print_result(d: dict) -> None:
    """Human-readable estimate (rounded to its uncertainty)."""
    def fmt(v, u, unit):
        if v is None:
            return "n/a"
        digits = max(0, 1 - int(math.floor(math.log10(u)))) if u and u > 0 else 3
        return f"{v:.{2}g} ± {u:.1g} {unit}" if digits == 0 else f"{v:.4g} ± {u:.2g} {unit}"

    print(f"effusivity  {fmt(d['effusivity_W_s05_m2K'], d['effusivity_W_s05_m2K_u'], 'W s^0.5/m^2/K')}")
    print(f"conductivity {fmt(d['k_W_mK'], d['k_W_mK_u'], 'W/m/K')}")
    print(f"diffusivity {fmt(d['alpha_m2_s'], d['alpha_m2_s_u'], 'm^2/s')}")
    if d["material"]:
        print(f"material    {d['material']} (confidence {d['material_confidence'] * 100:.0f} %)")
    print(f"method {d['method']}, model {d['model_sha256'][:12]}, flags: {', '.join(d['flags']) or 'none'}")


# --- entry point -----------------------------------------------------------------

_ADDERS = [_add_model, _add_train, _add_evaluate, _add_estimate]


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
