"""``thermotouch calibrate``: the probe's sensor chain from touches of reference materials (offline form).

``thermotouch calibrate --record A.csv --reference pmma --record B.csv --reference pyroceram --out CAL.json``
pairs each ``--record`` with the ``--reference`` that follows it (library names), fits the
thermopile's sensitivity, the sensing layer's effective depth and the thermocouple's lag
(:func:`edge.calibration.fit.fit_calibration`) and writes the calibration as JSON (atomically; an
existing file only with ``--overwrite``).  ``thermotouch estimate --calibration CAL.json`` uses it.
Records should start with the probe in air, before contact (see ``host/records.py``).
"""

from __future__ import annotations

import argparse

from host.cli.args import add_output, existing_file
from host.cli.errors import CliError


def add_parser(sub, parents):
    p = sub.add_parser("calibrate", help="calibrate the probe on touches of reference materials (offline records)",
                       parents=parents)
    p.add_argument("--record", action="append", type=existing_file, required=True, metavar="FILE.csv",
                   help="a touch of a reference, recorded from before contact (repeat; one per --reference)")
    p.add_argument("--reference", action="append", required=True, metavar="NAME",
                   help="library name of the material the preceding --record touched (default set: "
                        "pmma, pyroceram, aisi_304; at least two different)")
    p.add_argument("--probe", default="paper", help="probe head that took the records (default paper)")
    add_output(p, "--out", required=True, suffixes=(".json",), metavar="CAL.json", help="calibration file to write")
    p.add_argument("--json", action="store_true", help="print the calibration as JSON")
    p.set_defaults(func=run)


def run(args) -> int:
    from edge.calibration.fit import DEFAULT_REFERENCES, ReferenceTouch, fit_calibration  # noqa: PLC0415
    from edge.calibration.model import CalibrationError  # noqa: PLC0415
    from edge.physics.geometry import PROBES  # noqa: PLC0415
    from edge.physics.materials import load_materials  # noqa: PLC0415
    from host.atomic import write_text_atomic  # noqa: PLC0415
    from host.records import RecordError, read_record_metadata, read_series, uniform_series  # noqa: PLC0415

    if args.probe not in PROBES:
        raise CliError(f"--probe: unknown probe {args.probe!r}; shipped: {', '.join(PROBES)}")
    if len(args.record) != len(args.reference):
        raise CliError(f"give one --reference per --record ({len(args.record)} records, "
                       f"{len(args.reference)} references)")
    lib = load_materials()
    touches = []
    for path, name in zip(args.record, args.reference):
        try:
            m = lib.get(name)
        except KeyError:
            close = [n for n in lib.names() if name.lower() in n][:5] if hasattr(lib, "names") else []
            hint = f"; did you mean {', '.join(close)}?" if close else f"; defaults: {', '.join(DEFAULT_REFERENCES)}"
            raise CliError(f"--reference {name!r} is not a library material{hint}") from None
        try:
            recorded = read_record_metadata(path).get("probe")
            s = read_series(path)
            t, T, q = uniform_series(s["t_s"], s["T"], s["q_W_m2"], path=path)
        except RecordError as exc:
            raise CliError(f"--record {exc}") from None
        if recorded is not None and recorded != args.probe:
            raise CliError(f"--record {path} was taken with probe {recorded!r}, not --probe {args.probe}")
        touches.append(ReferenceTouch(name, m.solid.effusivity_W_s05_m2K, t, T, q))
    try:
        cal = fit_calibration(touches, probe=args.probe)
    except (CalibrationError, ValueError) as exc:
        raise CliError(f"calibration: {exc}") from None
    write_text_atomic(args.out, cal.to_json())
    if args.json:
        print(cal.to_json(), end="")
    else:
        c = cal.chain
        u = cal.u_theta
        print(f"calibration {cal.sha256[:12]} for probe {cal.probe} written to {args.out}")
        print(f"  flux sensor sensitivity  x {1.0 / c.flux_scale:.4f} of nominal  (u {u[0]:.1%})")
        print(f"  sensing depth            {c.sensing_thickness_m * 1e3:.4f} mm  (u {u[1]:.1%})")
        print(f"  sensing layer k          {c.k_W_mK:.4f} W/m/K  (u {u[3]:.1%})")
        print(f"  thermocouple lag         {c.tc_tau_s * 1e3:.1f} ms  (u {u[2] * 1e3:.1f} ms)")
        print(f"  transfer floor on e      {cal.u_rel_floor:.1%}")
        for r in cal.references:
            errs = ", ".join(f"{x:+.1%}" for x in r.rel_errors)
            print(f"  {r.name:<12} e {r.e_W_s05_m2K:.0f}: re-measured {errs}")
    return 0


def calibration_file(text: str):
    """``--calibration FILE``: a readable calibration (the error names the field at fault)."""
    from edge.calibration.model import CalibrationError, ProbeCalibration  # noqa: PLC0415

    path = existing_file(text)
    try:
        with open(path, "rb") as fh:
            data = fh.read(1 << 20)
        return ProbeCalibration.from_json(data)
    except OSError as exc:
        raise argparse.ArgumentTypeError(f"{text}: cannot read ({exc.strerror})") from None
    except CalibrationError as exc:
        raise argparse.ArgumentTypeError(f"{text}: {exc}") from None
