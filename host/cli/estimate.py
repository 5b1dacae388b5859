"""``thermotouch estimate``: e, k, alpha, the material and the object from a recorded series (CSV)."""

from __future__ import annotations

from host.cli.args import existing_file, positive_float
from host.cli.common import load_estimator, load_object_set
from host.cli.errors import CliError
from host.cli.report import dumps, print_result


def add_parser(sub, parents):
    p = sub.add_parser("estimate", help="e, k, alpha and the material from a recorded series", parents=parents)
    p.add_argument("--bundle", default=None, help="bundle directory (default: the shipped one)")
    p.add_argument("--csv", required=True, type=existing_file,
                   help="record: columns t_s, T_K or dT_K, q_W_m2 (UTF-8, a byte-order mark is fine)")
    p.add_argument("--method", choices=("paper", "default"), default="default")
    p.add_argument("--thickness", type=positive_float, default=None, help="known object thickness, m")
    p.add_argument("--back", choices=("insulated", "fixed"), default=None,
                   help="back boundary when --thickness is given (default insulated)")
    p.add_argument("--objects", metavar="OBJECTS.csv", type=existing_file, default=None,
                   help="name the object among your own (columns name, class, k_W_mK, rho_kg_m3, c_J_kgK or "
                        "e_W_s05_m2K, optional spread_rel; default: every library material)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=run)


def run(args) -> int:
    from edge.estimation.objects import LIBRARY_SET, ObjectSet, recognition_fields  # noqa: PLC0415
    from host.records import RecordError, read_record  # noqa: PLC0415

    if args.back is not None and args.thickness is None:
        raise CliError("--back needs --thickness (without it the object is semi-infinite)")
    # The object file is checked before the record: a bad file is the user's to fix first.
    if args.objects is not None:
        objects, _ = load_object_set(args.objects)
        set_name = str(args.objects)
    else:
        objects, set_name = ObjectSet.from_library(), LIBRARY_SET
    try:
        t, dT, q = read_record(args.csv)
    except RecordError as exc:
        raise CliError(f"--csv {exc}") from None
    est, _ = load_estimator(args.bundle, args.method)
    back = "infinite" if args.thickness is None else (args.back or "insulated")
    try:
        r = est.estimate(t, dT, q, method=args.method, thickness_m=args.thickness, back=back)
    except ValueError as exc:
        raise CliError(str(exc)) from None
    d = r.to_dict()
    d.update(recognition_fields(objects, d, set_name=set_name))
    if args.json:
        print(dumps(d))
    else:
        print_result(d)
    return 0
