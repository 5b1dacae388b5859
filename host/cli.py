"""``thermotouch``: the user's command line.

Every error a user can meet prints one line on stderr and exits non-zero
(2 for bad arguments or input, 1 for device or runtime failures); no
tracebacks.
"""

from __future__ import annotations

import argparse
import contextlib
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
    from edge.physics.solids import Solid

    if args.material is not None:
        from edge.physics.materials import load_materials

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
    from edge.physics.forward import simulate
    from edge.physics.probe import STACKS

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
    from edge.model.bundle import BundleError, load_bundle
    from edge.estimation.estimate import Estimator, pipeline_golden_check

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
    from pathlib import Path

    if Path(args.out).exists() and not args.overwrite:
        raise CliError(f"thermotouch train: {args.out} exists (use --overwrite)")
    bar = None

    def progress(i, n):
        nonlocal bar
        if tqdm is None:
            return
        if bar is None:
            bar = tqdm(total=n, desc="training set", unit="material", file=sys.stderr)
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


def _pm(v, u, unit, scale=1.0):
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


def print_result(d: dict) -> None:
    """Human-readable estimate (rounded to its uncertainty)."""
    print(f"effusivity   {_pm(d['effusivity_W_s05_m2K'], d['effusivity_W_s05_m2K_u'], 'W s^0.5/m^2/K')}")
    print(f"conductivity {_pm(d['k_W_mK'], d['k_W_mK_u'], 'W/m/K')}")
    print(f"diffusivity  {_pm(d['alpha_m2_s'], d['alpha_m2_s_u'], 'mm^2/s', 1e6)}")
    if d["material"]:
        print(f"material     {d['material']} (confidence {d['material_confidence'] * 100:.0f} %)")
    print(f"method {d['method']}, model {(d.get('model_sha256') or '')[:12]}, "
          f"flags: {', '.join(d['flags']) or 'none'}")


# --- the probe: sim, measure, info, history, flash, demo -------------------------------

def _add_device_args(p, *, sim_default=None):
    src = p.add_mutually_exclusive_group(required=sim_default is None)
    src.add_argument("--port", help="serial port of the probe (e.g. /dev/ttyACM0)")
    src.add_argument("--sim", default=sim_default, metavar="SCENE",
                     help="start a simulated probe on SCENE (shipped name or .toml) for the duration")
    p.add_argument("--workdir", default=None, help="with --sim: keep the simulated probe's models and history here")
    p.add_argument("--timeout", type=_float("--timeout"), default=3.0, help="reply timeout, s (default 3)")


@contextlib.contextmanager
def _device(args, prog):
    """open_device with every device problem turned into a one-line CliError."""
    from host.device import DeviceUnavailable, open_device

    try:
        with open_device(args.port, args.sim, workdir=args.workdir, timeout_s=args.timeout) as session:
            yield session
    except DeviceUnavailable as exc:
        raise CliError(f"{prog}: {exc}", exc.code) from None


def _add_sim(sub):
    p = sub.add_parser("sim", help="run a simulated probe on a virtual serial port until Ctrl-C")
    p.add_argument("scene", help="scene file (.toml) or shipped scene name")
    p.add_argument("--workdir", default=None, help="keep the model store and history here")
    p.set_defaults(func=cmd_sim)


def cmd_sim(args) -> int:
    import logging

    from firmware_sim.run import run_sim
    from host.device import DeviceUnavailable, validate_scene

    try:
        validate_scene(args.scene)
    except DeviceUnavailable as exc:
        raise CliError(f"thermotouch sim: {exc}", exc.code) from None
    logging.basicConfig(stream=sys.stderr, level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    return run_sim(args.scene, workdir=args.workdir)


def _add_measure(sub):
    p = sub.add_parser("measure", help="one touch: e, k and alpha with uncertainties, material, flags")
    _add_device_args(p)
    power = p.add_mutually_exclusive_group()
    power.add_argument("--voltage", type=_float("--voltage"), help="heater voltage, V")
    power.add_argument("--power", type=_float("--power"), help="heater power, W")
    timing = p.add_mutually_exclusive_group()
    timing.add_argument("--time", type=_float("--time"), help="contact (heating) time, s")
    timing.add_argument("--profile", choices=("quick", "standard", "precise"),
                        help="contact time of a measurement profile: quick 0.5 s, standard 2 s, precise 4 s "
                             "(accuracy per profile: README, estimation tables)")
    p.add_argument("--method", choices=("paper", "default"), default=None,
                   help="estimation method for this touch (default: the device's setting)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--plot", metavar="FILE.png", help="save measured and fitted flux and temperature")
    p.add_argument("--bundle", metavar="DIR", default=None,
                   help="with --plot: the device's model bundle, for the fitted curves (default: the shipped "
                        "bundle when the device runs it)")
    p.set_defaults(func=cmd_measure)


def _result_json(rec: dict) -> dict:
    out = dict(rec["result"])
    out.pop("candidates", None)
    out["flags"] = list(dict.fromkeys(list(rec.get("flags") or []) + list(out.get("flags") or [])))
    out.update(measurement_id=rec["measurement_id"], power_W=rec.get("power_W"),
               contact_time_s=rec.get("contact_time_s"))
    return out


def cmd_measure(args) -> int:
    from host.device import DeviceUnavailable
    from host.touch import touch

    prog = "thermotouch measure"
    if args.profile is not None:
        from edge.measure.profiles import PROFILES

        args.time = PROFILES[args.profile].contact_time_s
    if args.bundle is not None:
        from host.touch import bundle_identity

        if not args.plot:
            raise CliError(f"{prog}: --bundle is for the fitted curves of --plot", 2)
        try:
            bundle_identity(args.bundle)  # a wrong directory is refused before the touch
        except DeviceUnavailable as exc:
            raise CliError(f"{prog}: {exc}", exc.code) from None
    with _device(args, prog) as session:
        try:
            t = touch(session, power_W=args.power, voltage_V=args.voltage, contact_time_s=args.time,
                      method=args.method, with_series=bool(args.plot), bundle_dir=args.bundle)
        except DeviceUnavailable as exc:
            raise CliError(f"{prog}: {exc}", exc.code) from None
        d = _result_json(t.record)
        if args.plot:
            from host.plots import plot_touch

            fit = t.fits.get(d["method"])
            label = session.simulator.scene.name if session.simulated else session.port
            if fit is None:
                label += f" (measured series only: {t.fit_note or 'no model fit'})"
            try:
                plot_touch(args.plot, t.series, d, fit, label)
            except OSError as exc:
                raise CliError(f"{prog}: cannot write {args.plot}: {exc}", 1) from None
    if args.json:
        print(json.dumps(d))
        return 0
    print(f"measurement {d['measurement_id']}: {d['power_W']:.3g} W for {d['contact_time_s']:.3g} s")
    print_result(d)
    if args.plot:
        print(f"plot: {args.plot}" + ("" if t.fits.get(d["method"]) is not None
                                      else f" (measured series only: {t.fit_note or 'no model fit'})"))
    return 0


def _add_info(sub):
    p = sub.add_parser("info", help="firmware, model and board of the probe")
    _add_device_args(p)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_info)


def cmd_info(args) -> int:
    with _device(args, "thermotouch info") as session:
        info = session.client.info()
        status = session.client.status()
    if args.json:
        print(json.dumps({"info": info, "status": status}))
        return 0
    print(f"port       {session.port}")
    print(f"board      {info['board']}, firmware {info['firmware_version']}, protocol {info['protocol_version']}")
    print(f"model      {info.get('model_version')} (sha256 {info.get('model_sha256')}, "
          f"{info.get('model_source') or 'unknown source'})")
    print(f"state      {status['state']}, {status.get('history_total', 0)} measurement(s) stored")
    return 0


def _add_history(sub):
    p = sub.add_parser("history", help="the probe's stored measurements, newest first")
    _add_device_args(p)
    p.add_argument("--json", action="store_true", help="print one JSON list")
    p.add_argument("--export", metavar="CSV", help="write every record to a CSV file")
    p.add_argument("--limit", type=int, default=None, help="at most this many records (default: all)")
    p.set_defaults(func=cmd_history)


HISTORY_CSV_COLUMNS = (
    "measurement_id", "created_utc", "started_utc", "status", "reason", "power_W", "contact_time_s",
    "heater_on_s", "T0_C", "effusivity_W_s05_m2K", "effusivity_W_s05_m2K_u", "k_W_mK", "k_W_mK_u",
    "alpha_m2_s", "alpha_m2_s_u", "material", "material_confidence", "method", "model_sha256", "flags",
)


def _history_row(item: dict) -> dict:
    r = item.get("result") or {}
    row = {k: item.get(k) for k in HISTORY_CSV_COLUMNS}
    for k in ("effusivity_W_s05_m2K", "effusivity_W_s05_m2K_u", "k_W_mK", "k_W_mK_u", "alpha_m2_s",
              "alpha_m2_s_u", "material", "material_confidence", "method"):
        row[k] = r.get(k)
    row["model_sha256"] = item.get("model_sha256") or r.get("model_sha256")
    row["flags"] = " ".join(item.get("flags") or [])
    return row


def cmd_history(args) -> int:
    import csv

    items: list[dict] = []
    with _device(args, "thermotouch history") as session:
        offset = 0
        while True:
            page = session.client.history(offset=offset, limit=100)
            items.extend(page["items"])
            offset += len(page["items"])
            if not page["items"] or offset >= page["total"] or (args.limit and len(items) >= args.limit):
                break
    if args.limit:
        items = items[:args.limit]
    if args.export:
        try:
            with open(args.export, "w", newline="") as fh:
                w = csv.DictWriter(fh, fieldnames=HISTORY_CSV_COLUMNS)
                w.writeheader()
                for it in items:
                    w.writerow(_history_row(it))
        except OSError as exc:
            raise CliError(f"thermotouch history: cannot write {args.export}: {exc}", 1) from None
    if args.json:
        print(json.dumps(items))
        return 0
    print(f"{len(items)} measurement(s)" + (f"; exported to {args.export}" if args.export else ""))
    if items:
        print(f"{'id':>5} {'started (UTC)':20} {'status':8} {'e':>9} {'k W/m/K':>9} {'α mm²/s':>9} "
              f"{'material':24} flags")
    for it in items:
        r = _history_row(it)
        f = lambda v, s=1.0: "-" if v is None else f"{v * s:.4g}"
        print(f"{r['measurement_id']:>5} {str(r['started_utc'] or '')[:19]:20} {r['status']:8} "
              f"{f(r['effusivity_W_s05_m2K']):>9} {f(r['k_W_mK']):>9} {f(r['alpha_m2_s'], 1e6):>9} "
              f"{str(r['material'] or '-'):24} {r['flags'] or '-'}")
    return 0


def _add_flash(sub):
    p = sub.add_parser("flash", help="verify a model bundle and install it on the probe")
    p.add_argument("bundle", help="bundle directory (e.g. from 'thermotouch train')")
    _add_device_args(p)
    p.set_defaults(func=cmd_flash)


def cmd_flash(args) -> int:
    from host.flash import flash_bundle, load_verified
    from host.device import DeviceUnavailable

    prog = "thermotouch flash"
    try:
        load_verified(args.bundle)  # refuse a bad bundle before touching the device
    except DeviceUnavailable as exc:
        raise CliError(f"{prog}: {exc}", exc.code) from None
    with _device(args, prog) as session:
        try:
            r = flash_bundle(session, args.bundle)
        except DeviceUnavailable as exc:
            raise CliError(f"{prog}: {exc}", exc.code) from None
    print(f"flashed {args.bundle} ({r['bytes']} B): device runs {r['model_version']} "
          f"sha256 {r['model_sha256']}")
    return 0


def _add_demo(sub):
    p = sub.add_parser("demo", help="simulated probe: deploy a model, touch the paper's samples, print and plot")
    p.add_argument("--train", action="store_true", help="train a quick model and deploy it instead of the shipped one")
    p.add_argument("--out", default="thermotouch-demo", help="output directory (default ./thermotouch-demo)")
    p.set_defaults(func=cmd_demo)


def cmd_demo(args) -> int:
    from host.demo import run_demo
    from host.device import DeviceUnavailable

    try:
        return run_demo(args.out, train=args.train)
    except DeviceUnavailable as exc:
        raise CliError(f"thermotouch demo: {exc}", exc.code) from None


# --- entry point -----------------------------------------------------------------

_ADDERS = [_add_model, _add_train, _add_evaluate, _add_estimate, _add_sim, _add_measure, _add_info, _add_history,
           _add_flash, _add_demo]


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="thermotouch", description="ThermoTouch contact thermal-property probe")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for add in _ADDERS:
        add(sub)
    return parser


def main(argv=None) -> int:
    from host.blas import limit_blas_threads

    limit_blas_threads()
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
    except Exception as exc:  # a bug: still one line for the user; THERMOTOUCH_DEBUG=1 shows the traceback
        import os

        if os.environ.get("THERMOTOUCH_DEBUG"):
            raise
        print(f"thermotouch: internal error: {type(exc).__name__}: {exc} (set THERMOTOUCH_DEBUG=1 for details)",
              file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
