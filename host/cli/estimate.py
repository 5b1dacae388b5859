"""``thermotouch estimate``: e, k, alpha, the material and the object from a recorded series (CSV)."""

from __future__ import annotations

import argparse

from host.cli.args import existing_file, positive_float
from host.cli.calibrate import calibration_file
from host.cli.common import load_estimator, load_object_set
from host.cli.errors import CliError
from host.cli.report import dumps, print_result


def probe_name(text: str) -> str:
    """A shipped probe head (a name in :data:`edge.physics.geometry.PROBES`)."""
    from edge.physics.geometry import PROBES  # noqa: PLC0415

    if text not in PROBES:
        raise argparse.ArgumentTypeError(f"unknown probe {text!r}; shipped: {', '.join(PROBES)}")
    return text


def add_parser(sub, parents):
    p = sub.add_parser("estimate", help="e, k, alpha and the material from a recorded series", parents=parents)
    p.add_argument("--bundle", default=None, help="bundle directory (default: the shipped one)")
    p.add_argument("--csv", required=True, type=existing_file,
                   help="record: columns t_s, T_K or dT_K, q_W_m2 (UTF-8, a byte-order mark is fine); "
                        "a '# probe: NAME' comment before the header must match --probe")
    p.add_argument("--probe", type=probe_name, default="paper",
                   help="probe head that took the record: paper (1-D, default) or small-heater "
                        "(axisymmetric fit of k and alpha; T is its thermocouple, q its flux sensor)")
    p.add_argument("--method", choices=("paper", "default"), default=None,
                   help="paper probe only: default or paper (default: default)")
    p.add_argument("--thickness", type=positive_float, default=None, help="known object thickness, m")
    p.add_argument("--back", choices=("insulated", "fixed"), default=None,
                   help="back boundary when --thickness is given (default insulated)")
    p.add_argument("--objects", metavar="OBJECTS.csv", type=existing_file, default=None,
                   help="name the object among your own (columns name, class, k_W_mK, rho_kg_m3, c_J_kgK or "
                        "e_W_s05_m2K, optional spread_rel; default: every library material)")
    p.add_argument("--calibration", metavar="CAL.json", type=calibration_file, default=None,
                   help="the probe's calibration (from `thermotouch calibrate`, for --probe's probe). Paper probe: "
                        "fit e, the contact resistance and the object's temperature from the moment of contact "
                        "through its sensor chain (the record should start before contact); small heater: its "
                        "flux sensor's scale and uncertainty. Without it results are flagged 'uncalibrated'")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=run)


def run(args) -> int:
    from edge.recognition import LIBRARY_SET, ObjectSet, recognition_fields  # noqa: PLC0415
    from host.records import RecordError, read_record, read_record_metadata  # noqa: PLC0415

    if args.back is not None and args.thickness is None:
        raise CliError("--back needs --thickness (without it the object is semi-infinite)")
    if args.probe != "paper" and args.method is not None:
        # The paper's network was trained on the paper's probe; the small heater has one method.
        raise CliError(f"--method is for the paper probe; --probe {args.probe} uses the axisymmetric fit")
    method = args.method or "default"
    if args.calibration is not None:
        if args.calibration.probe != args.probe:
            # Another probe's calibration would be applied to the wrong sensors: refuse, never ignore.
            raise CliError(f"--calibration is for probe {args.calibration.probe!r}, not --probe {args.probe}")
        if args.probe == "paper" and (args.method is not None or args.thickness is not None):
            raise CliError("--calibration fits a thick object from contact; it does not combine with --method or --thickness")
    # The object file is checked before the record: a bad file is the user's to fix first.
    if args.objects is not None:
        objects, _ = load_object_set(args.objects)
        set_name = str(args.objects)
    else:
        objects, set_name = ObjectSet.from_library(), LIBRARY_SET
    try:
        recorded = read_record_metadata(args.csv).get("probe")
        t, dT, q = read_record(args.csv)
    except RecordError as exc:
        raise CliError(f"--csv {exc}") from None
    if recorded is not None and recorded != args.probe:
        # A record estimated with another probe's geometry gives confident nonsense: refuse.
        raise CliError(f"--csv {args.csv} was taken with probe {recorded!r}, not --probe {args.probe}")
    if args.calibration is not None and args.probe == "paper":
        return _run_chain(args, objects, set_name)
    est, _ = load_estimator(args.bundle, method)
    back = "infinite" if args.thickness is None else (args.back or "insulated")
    try:
        if args.probe == "paper":
            d = est.estimate(t, dT, q, method=method, thickness_m=args.thickness, back=back).to_dict()
        else:
            from edge.estimation.probe_estimate import AxiEstimator  # noqa: PLC0415

            cal = {} if args.calibration is None else {"flux_scale": args.calibration.chain.flux_scale,
                                                       "flux_u_rel": float(args.calibration.u_theta[0])}
            d = AxiEstimator(est, args.probe).estimate(t, dT, q, thickness_m=args.thickness, back=back, **cal)
    except ValueError as exc:
        raise CliError(str(exc)) from None
    if args.calibration is None:
        # No calibration: the datasheet chain -- say so on every result (ISSUE #10 §4).
        d["flags"] = list(dict.fromkeys(list(d.get("flags") or []) + ["uncalibrated"]))
    else:
        d["calibration_sha256"] = args.calibration.sha256
    d.update(recognition_fields(objects, d, set_name=set_name))
    if args.json:
        print(dumps(d))
    else:
        print_result(d)
    return 0


def _run_chain(args, objects, set_name) -> int:
    """``--calibration``: the sensor-chain estimate from contact (:mod:`edge.estimation.chain_estimate`)."""
    from edge.estimation.chain_estimate import estimate_from_contact  # noqa: PLC0415
    from edge.recognition import recognition_fields  # noqa: PLC0415
    from host.records import RecordError, read_series, uniform_series  # noqa: PLC0415

    try:
        s = read_series(args.csv)
        t, T, q = uniform_series(s["t_s"], s["T"], s["q_W_m2"], path=args.csv)
    except RecordError as exc:
        raise CliError(f"--csv {exc}") from None
    try:
        d = estimate_from_contact(t, T, q, args.calibration)
    except ValueError as exc:
        raise CliError(f"--csv {args.csv}: {exc}") from None
    d["method"] = "sensor_chain"
    if d.get("effusivity_W_s05_m2K") is not None:
        d.update(recognition_fields(objects, d, set_name=set_name))
    if args.json:
        print(dumps(d))
    else:
        _print_chain(d)
    return 0 if d.get("effusivity_W_s05_m2K") is not None else 1


def _print_chain(d: dict) -> None:
    if d.get("effusivity_W_s05_m2K") is None:
        print(f"no estimate: {', '.join(d['flags'])}")
        return
    e, u = d["effusivity_W_s05_m2K"], d["effusivity_W_s05_m2K_u"]
    print(f"e      {e:.1f} +- {u:.1f} W s^0.5/m^2/K  ({u / e:.1%}, k = 1)")
    print(f"R_c    {d['contact_resistance_m2K_W']:.2e} +- {d['contact_resistance_m2K_W_u']:.1e} m^2 K/W")
    print(f"T_obj0 {d['object_temperature0']:.3f} +- {d['object_temperature0_u']:.3f} (probe {d['probe_temperature0']:.3f})")
    print(f"contact at t = {d['contact_t_s']:.3f} s ({'detected' if d['contact_detected'] else 'not seen'}), "
          f"normalised residual {d['normalised_residual']:.2f}")
    if d.get("object") is not None:
        print(f"object {d['object']} ({d['object_posterior']:.2f}), class {d['class']}")
    print(f"flags  {', '.join(d['flags']) or '-'}")
