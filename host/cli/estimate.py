"""``thermotouch estimate``: e, k, alpha, the material and the object from a recorded series (CSV)."""

from __future__ import annotations

import argparse
import sys

from host.cli.args import existing_file, positive_float, probe_name
from host.cli.calibrate import calibration_file
from host.cli.common import load_object_set, seam_context
from host.cli.errors import EXIT_RUNTIME, CliError
from host.cli.report import dumps, print_result
from host.records import CHECKS


def add_parser(sub, parents):
    p = sub.add_parser("estimate", help="e, k, alpha and the material from a recorded series", parents=parents)
    p.add_argument("--bundle", default=None, help="bundle directory (default: the shipped one)")
    p.add_argument("--csv", required=True, type=existing_file,
                   help="record: a device's export (`history --export-series`: its header names the probe, power, "
                        "sample clock and settings the device used, and the estimate is the device's) or an older "
                        "CSV with columns t_s, T_C, T_K or dT_K, q_W_m2 (UTF-8, a byte-order mark is fine); a "
                        "'# probe: NAME' line before the header must match --probe")
    p.add_argument("--probe", type=probe_name, default=None,
                   help="probe head that took the record: paper (1-D) or small-heater (axisymmetric fit of k and "
                        "alpha; T is its thermocouple, q its flux sensor); default: the export's, else paper")
    p.add_argument("--method", choices=("paper", "default"), default=None,
                   help="paper probe only: default or paper (default: the export's, else default)")
    p.add_argument("--thickness", type=positive_float, default=None, help="known object thickness, m")
    p.add_argument("--back", choices=("insulated", "fixed"), default=None,
                   help="back boundary when --thickness is given (default insulated)")
    p.add_argument("--objects", metavar="OBJECTS.csv", type=existing_file, default=None,
                   help="name the object among your own (columns name, class, k_W_mK, rho_kg_m3, c_J_kgK or "
                        "e_W_s05_m2K, optional spread_rel; default: every library material, as the device "
                        "without an object set)")
    p.add_argument("--calibration", metavar="CAL.json", type=calibration_file, default=None,
                   help="the probe's calibration (from `thermotouch calibrate`, for the record's probe). Paper "
                        "probe: the sensor chain fits e, the contact resistance and the object's temperature "
                        "from the moment of contact (the record should start before contact) and its e is the "
                        "answer when it describes the record; small heater: its flux sensor's scale and "
                        "uncertainty. Without it results are flagged 'uncalibrated'")
    p.add_argument("--accept", action="append", default=[], metavar="CHECK", type=_check_name,
                   help="a record check to waive when the record is right although it looks wrong (repeatable): "
                        + "; ".join(f"{k}: {v}" for k, v in CHECKS.items()))
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=run)


def _check_name(text: str) -> str:
    """A record check's name (:data:`host.records.CHECKS`)."""
    if text not in CHECKS:
        raise argparse.ArgumentTypeError(f"unknown check {text!r}; checks: {', '.join(CHECKS)}")
    return text


def _check_method(probe: str, args) -> type:
    """The probe head's estimator class; refuses options it does not take (before any work)."""
    from edge.estimation.methods import method_class  # noqa: PLC0415

    cls = method_class(probe)
    if args.method is not None and cls.kind != "thick_body":
        # The paper's network was trained on the 1-D (thick-body) probe; other heads have one method.
        raise CliError(f"--method is for the paper probe's 1-D estimator; --probe {probe} uses the {cls.kind} fit")
    cal = args.calibration
    if cal is not None:
        if cal.probe != probe:
            # Another probe's calibration would be applied to the wrong sensors: refuse, never ignore.
            raise CliError(f"--calibration is for probe {cal.probe!r}, not --probe {probe}")
        if cls.sensor_chain and (args.method is not None or args.thickness is not None):
            raise CliError("--calibration fits a thick object from contact; it does not combine with --method or "
                           "--thickness")
    return cls


def _thresholds(meta: dict):
    """The ``[measurement]`` settings the device judged the touch by (``measurement.*`` header lines),
    over the shipped defaults; None when the record names none (the context then takes the defaults)."""
    from edge.service.config import Config, ConfigError  # noqa: PLC0415

    given = {k: v for k, v in meta.items() if k.startswith("measurement.")}
    if not given:
        return None
    base = Config()
    updates = {}
    for key, text in given.items():
        try:
            current = base.get(key)
        except (KeyError, ConfigError):
            continue  # a setting this software does not know cannot change its estimate
        if isinstance(current, bool):
            updates[key] = str(text).strip().lower() in ("true", "1", "yes")
        elif isinstance(current, (int, float)):
            try:
                updates[key] = type(current)(float(text))
            except ValueError:
                raise CliError(f"--csv header {key}: expected a number, got {text!r}") from None
    try:
        return base.with_updates(updates, runtime_only=False).measurement
    except ConfigError as exc:
        raise CliError(f"--csv header: {exc}") from None


def _decision(meta: dict) -> dict | None:
    """The device's running decision (a ``decision`` header line: one line of JSON), if recorded."""
    import json  # noqa: PLC0415

    text = meta.get("decision")
    if text is None or str(text).strip().lower() in ("", "none", "null"):
        return None
    try:
        d = json.loads(text)
    except ValueError:
        raise CliError("--csv header decision: not one line of JSON") from None
    return d if isinstance(d, dict) else None


def _differences(meta: dict, model_sha256: str | None, calibration) -> list[str]:
    """Where this estimate's context differs from the device's (an export names its model and calibration):
    the answer is then not the device's, and the user should know why."""
    if "measurement_id" not in meta:
        return []  # not a device's export: nothing to compare with
    out = []
    device_model = meta.get("model_sha256")
    if device_model and model_sha256 and device_model != model_sha256:
        out.append(f"the device used model {device_model[:12]}, this estimate model {model_sha256[:12]} "
                   "(--bundle): the answer differs from the device's")
    device_cal = meta.get("calibration_sha256")
    mine = None if calibration is None else calibration.sha256
    if device_cal != mine and meta.get("status", "ok") == "ok":
        said = "no calibration" if device_cal is None else f"calibration {device_cal[:12]}"
        given = "none" if mine is None else mine[:12]
        out.append(f"the device used {said}, this estimate --calibration {given}: the answer differs from the "
                   "device's")
    return out


def run(args) -> int:
    from dataclasses import replace  # noqa: PLC0415

    from edge.recognition import LIBRARY_SET, ObjectSet  # noqa: PLC0415
    from edge.estimation.record import RecordError as BadRecord  # noqa: PLC0415
    from edge.estimation.seam import estimate_touch  # noqa: PLC0415
    from host.records import RecordError, read_touch  # noqa: PLC0415

    if args.back is not None and args.thickness is None:
        raise CliError("--back needs --thickness (without it the object is semi-infinite)")
    if args.probe is not None:
        _check_method(args.probe, args)
    # The object file is checked before the record: a bad file is the user's to fix first.
    if args.objects is not None:
        objects, _ = load_object_set(args.objects)
        set_name = str(args.objects)
    else:
        objects, set_name = ObjectSet.from_library(), LIBRARY_SET
    try:
        record = read_touch(args.csv, probe=args.probe, accept=args.accept)
    except RecordError as exc:
        raise CliError(f"--csv {exc}") from None
    _check_method(record.probe, args)
    status = record.meta.get("status")
    if status is not None and status != "ok":
        # The device estimates only a touch that ended well; an export of one that failed or was cut
        # short has no device answer to reproduce, and an estimate of its partial record would be a guess.
        why = record.meta.get("reason")
        raise CliError(f"--csv {args.csv}: measurement {record.meta.get('measurement_id', '?')} ended {status}"
                       f"{f' ({why})' if why else ''} on the device: no estimate", EXIT_RUNTIME)
    if args.method is not None and args.method != record.method:
        try:
            record = replace(record, method=args.method)
        except BadRecord as exc:
            raise CliError(f"--csv {args.csv}: {exc}") from None
    # The device's context: its model (the bundle), calibration, object set and the [measurement]
    # thresholds its export names (an older CSV: the defaults a device runs with).
    context = seam_context(args.bundle, calibration=args.calibration, object_set=objects, object_set_name=set_name,
                           thresholds=_thresholds(dict(record.meta)), method=record.method,
                           thickness_m=args.thickness,
                           back="infinite" if args.thickness is None else (args.back or "insulated"))
    for note in _differences(record.meta, getattr(context.estimator, "sha256", None), args.calibration):
        print(f"note: {note}", file=sys.stderr)
    try:
        answer = estimate_touch(record, context, decision=_decision(dict(record.meta)))
    except ValueError as exc:
        if args.json:
            # A refusal is an answer too: every key, object "unknown" (ISSUE #37), and why.
            print(dumps(_refusal(record.probe, set_name, exc)), flush=True)
        raise CliError(f"--csv {args.csv}: {exc}") from None
    d = answer.to_dict()
    if args.json:
        print(dumps(d), flush=True)
    elif d.get("effusivity_W_s05_m2K") is not None:
        # An object the set cannot name has no posteriors to print.
        print_result(d if d.get("object_posterior") is not None else dict(d, object=None))
        chain = d.get("sensor_chain")
        if isinstance(chain, dict) and chain.get("effusivity_W_s05_m2K") is not None:
            print(_chain_line(chain))
    if d.get("effusivity_W_s05_m2K") is None:  # no answer is not a success, as for measure
        raise CliError(f"--csv {args.csv} gave no estimate"
                       + (f" (flags: {', '.join(d['flags'])})" if d.get("flags") else ""), EXIT_RUNTIME)
    return 0


def _refusal(probe: str, set_name: str | None, exc: Exception) -> dict:
    """The JSON of a touch the estimate path refused: the result's keys, no values, object ``unknown``."""
    from edge.estimation.result import Estimate, unknown_recognition  # noqa: PLC0415

    return {**Estimate(probe=probe, method="none").to_dict(), **unknown_recognition(set_name), "error": str(exc)}


def _chain_line(c: dict) -> str:
    """The calibrated sensor chain's own fit: its e, the contact resistance, the object's temperature, the contact."""
    def num(key: str, fmt: str) -> str:
        v = c.get(key)
        return "n/a" if v is None else format(v, fmt)

    return (f"sensor chain e {num('effusivity_W_s05_m2K', '.1f')} ± {num('effusivity_W_s05_m2K_u', '.1f')}, "
            f"R_c {num('contact_resistance_m2K_W', '.2e')} ± {num('contact_resistance_m2K_W_u', '.1e')} m^2 K/W, "
            f"T_obj0 {num('object_temperature0', '.3f')} ± {num('object_temperature0_u', '.3f')} degC, "
            f"contact at t = {num('contact_t_s', '.3f')} s, normalised residual {num('normalised_residual', '.2f')}, "
            f"flags {', '.join(c.get('flags') or []) or '-'}")
