"""``thermotouch calibrate``: the probe's sensor chain from touches of reference materials.

Fit (offline)::

    thermotouch calibrate --record A.csv --reference pmma --record B.csv --reference pyroceram --out CAL.json

pairs each ``--record`` with the ``--reference`` that follows it (library names), fits the
thermopile's sensitivity, the sensing layer's effective depth and conductivity and the
thermocouple's lag (:func:`edge.calibration.fit.fit_calibration`) and writes the calibration as
JSON (atomically; an existing file only with ``--overwrite``).  ``thermotouch estimate
--calibration CAL.json`` uses it.  Records should start with the probe in air, before contact (see
``host/records.py``).

Every fit checks itself (ISSUE #34): each reference is re-measured -- through the one estimate
path, :func:`edge.estimation.seam.estimate_touch` -- by the calibration fitted without it, and the
misses must pass a chi^2 test at p = 0.99 (:mod:`edge.calibration.selfcheck`); otherwise the
calibration is refused (exit 2, one line naming the reference and its miss) unless ``--force``,
which writes it flagged ``forced`` with a model-form floor (``u_rel_floor``) covering the misses.
The references' ``rel_errors`` are what ``thermotouch estimate`` answers on the same record with
the written file.  Refused before fitting: records of another probe head (their ``# probe:``
line), records without the samples in air before contact, a touch whose datasheet e is outside
x 2 (+ 3 u) of its declared reference (swapped names), records of two devices.  The file names the
device it is for: the walk-through's INFO ``device_id``, or the exports' ``# device_id:`` header
(none: a file only a device that allows unsigned updates takes).

On the probe (``--port PORT`` or ``--sim SCENE``)::

    thermotouch calibrate --install CAL.json [--key SECRET.json]   # verified, signed, stored atomically
    thermotouch calibrate --show                                     # the installed one, or none
    thermotouch calibrate --check --reference pmma                   # touch a reference: does it still hold?

With ``--out`` as well, ``--record``/``--reference`` fit and ``--port``/``--sim`` install in one go.

Walk-through (no ``--record``)::

    thermotouch calibrate --port PORT [--reference NAME ...] --out CAL.json [--key SECRET.json]
    thermotouch calibrate --sim SCENE [--reference NAME ...] --out CAL.json [--workdir DIR]

touches each reference in turn (default pmma, pyroceram, aisi_304): the device is armed, samples
the air, finds the contact, heats ``--settle`` after it for ``--heat`` seconds; the host fits its
raw records, writes ``--out`` and installs the calibration.  On a port the user is asked to lift
the probe and touch each reference (Enter to go on, when stdin is a terminal); on ``--sim`` each
reference is the scene with that material as its object (its as-built probe, board and contact
unchanged), all on one simulated probe's storage (``--workdir`` keeps it).  A touch that does not
come, or a record that starts in contact, stops the walk with nothing installed.
"""

from __future__ import annotations

import argparse

from host.cli.args import add_device_args, add_output, existing_file, measure_bound, probe_name
from host.cli.common import device_call, device_session
from host.cli.errors import CliError
from host.cli.report import dumps


def add_parser(sub, parents):
    p = sub.add_parser("calibrate", help="the probe's calibration on reference materials: fit from records, install, "
                                        "show, check",
                       parents=parents)
    p.add_argument("--record", action="append", type=existing_file, default=[], metavar="FILE.csv",
                   help="a touch of a reference, recorded from before contact (repeat; one per --reference)")
    p.add_argument("--reference", action="append", default=[], metavar="NAME",
                   help="library name of the material the preceding --record touched (default set: "
                        "pmma, pyroceram, aisi_304; at least two different); with --check, the one touched")
    p.add_argument("--probe", type=probe_name, default="paper", help="probe head that took the records (default paper)")
    add_output(p, "--out", suffixes=(".json",), metavar="CAL.json", default=None,
               help="calibration file to write (the fit)")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--install", metavar="CAL.json", type=existing_file, default=None,
                      help="install this calibration on the probe (--port or --sim)")
    mode.add_argument("--show", action="store_true", help="show the probe's installed calibration")
    mode.add_argument("--check", action="store_true",
                      help="touch one --reference now and say whether the installed calibration still holds")
    p.add_argument("--key", metavar="SECRET.json", type=existing_file, default=None,
                   help="sign what is installed with this secret key (thermotouch keys new)")
    conv, rng = measure_bound("contact_time_s")
    # One flag per concept across verbs: contact (heating) time is --time (--heat, its old name, still works).
    p.add_argument("--time", type=conv, default=None, metavar="S", dest="heat",
                   help=f"walk-through: heating time of each reference touch ({rng}; default 8 s)")
    p.add_argument("--heat", type=conv, dest="heat", default=argparse.SUPPRESS, help=argparse.SUPPRESS)
    conv, rng = measure_bound("arm_s")
    p.add_argument("--arm", type=conv, default=30.0, metavar="S",
                   help=f"walk-through: how long the device waits for each touch ({rng}; default 30 s)")
    conv, rng = measure_bound("settle_s")
    p.add_argument("--settle", type=conv, default=1.0, metavar="S",
                   help=f"walk-through: contact to heater-on ({rng}; default 1 s)")
    p.add_argument("--force", action="store_true",
                   help="write (and install) a calibration whose leave-one-reference-out self-check failed: "
                        "flagged 'forced', with a model-form floor that covers its misses")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    add_device_args(p, sim_help="start a simulated probe on SCENE (shipped name or .toml) for --install/--show/"
                                "--check (keep it with --workdir)")
    p.set_defaults(func=run)


def run(args) -> int:
    on_device = args.install is not None or args.show or args.check
    device = getattr(args, "port", None) is not None or getattr(args, "sim", None) is not None
    if args.check:
        if len(args.reference) != 1 or args.record:
            raise CliError("--check touches one reference: give exactly one --reference (and no --record)")
        return _run_check(args)
    if args.show:
        if args.record or args.reference or args.out is not None:
            raise CliError("--show takes no --record, --reference or --out")
        return _run_show(args)
    if args.install is not None:
        if args.record or args.reference or args.out is not None:
            raise CliError("--install takes a calibration file; --record/--reference/--out are for the fit")
        return _run_install(args, _read_calibration_file(args.install))
    if not args.record and (device or _port_from_env()):
        return _run_walk(args)
    if not args.record:
        raise CliError("give --record FILE --reference NAME pairs and --out CAL.json (the fit), --port/--sim with "
                       "--out CAL.json (the walk-through), or --install, --show or --check with --port/--sim")
    if args.out is None:
        raise CliError("the fit needs --out CAL.json (where the calibration is written)")
    cal = _fit(args)
    if device and not on_device:
        # Fit and install in one go.
        _run_install(args, cal)
    return 0


def _port_from_env() -> bool:
    import os  # noqa: PLC0415

    from host.cli.args import PORT_ENV  # noqa: PLC0415

    return bool(os.environ.get(PORT_ENV, "").strip())


def _run_walk(args) -> int:
    """Touch each reference on the probe, fit, write ``--out``, install (see the module docstring)."""
    import contextlib  # noqa: PLC0415
    import sys  # noqa: PLC0415
    import tempfile  # noqa: PLC0415

    from edge.calibration.fit import DEFAULT_REFERENCES, fit_calibration  # noqa: PLC0415
    from edge.physics.materials import load_materials  # noqa: PLC0415
    from host.atomic import write_text_atomic  # noqa: PLC0415
    from host.calibration import HEAT_s, WalkError, install_calibration, reference_scene, touch_reference  # noqa: PLC0415
    from host.cli.args import resolve_port  # noqa: PLC0415
    from host.device import open_device  # noqa: PLC0415
    from host.flash import load_signing_key  # noqa: PLC0415

    if args.out is None:
        raise CliError("the walk-through needs --out CAL.json (the calibration is kept on the host too)")
    from edge.estimation.methods import method_class  # noqa: PLC0415

    if not method_class(args.probe).sensor_chain:
        from edge.physics.geometry import PROBES  # noqa: PLC0415

        chained = [p for p in PROBES if method_class(p).sensor_chain]
        raise CliError(f"--probe {args.probe}: the sensor-chain calibration exists for the {' and '.join(chained)} "
                       f"probe{'s' if len(chained) > 1 else ''} only (this probe head's estimator has no sensor "
                       "chain: fit its flux scale from --record/--reference pairs)")
    if not args.arm > 0:
        raise CliError("--arm must be > 0 for the walk-through (the device waits that long for each touch)")
    names = args.reference or list(DEFAULT_REFERENCES)
    if len(set(names)) < 2:
        raise CliError("calibration needs at least two different --reference materials")
    lib = load_materials()
    refs = {n: _reference(lib, n) for n in names}
    heat = HEAT_s if args.heat is None else args.heat
    key = load_signing_key(args.key)   # a bad key file is refused before any touch
    resolve_port(args)
    say = (lambda m: print(m, file=sys.stderr)) if args.json else print  # noqa: E731
    interactive = args.port is not None and sys.stdin.isatty()
    with contextlib.ExitStack() as stack:
        workdir = args.workdir
        if args.sim is not None and workdir is None:
            workdir = stack.enter_context(tempfile.TemporaryDirectory(prefix="thermotouch-calibrate-"))
        scenes = None if args.sim is None else stack.enter_context(
            tempfile.TemporaryDirectory(prefix="thermotouch-references-"))
        port_session = None
        if args.port is not None:
            port_session = stack.enter_context(open_device(args.port, None, timeout_s=args.timeout))

        def session_for(name):
            if port_session is not None:
                return contextlib.nullcontext(port_session)
            try:
                path = reference_scene(args.sim, name, scenes, heat_s=heat, settle_s=args.settle)
            except (OSError, ValueError) as exc:
                raise CliError(f"--sim {args.sim}: {exc}") from None
            return open_device(None, str(path), workdir=workdir, timeout_s=args.timeout)

        touches, records = [], []
        for i, name in enumerate(names, 1):
            e_ref = refs[name].solid.effusivity_W_s05_m2K
            say(f"reference {i}/{len(names)}: {name} (e {e_ref:.0f}). Hold the probe in the air, then put it on "
                f"the {name} within {args.arm:g} s; keep it there {args.settle + heat:g} s.")
            if interactive:
                input("press Enter when the probe is in the air ... ")
            with session_for(name) as session:
                try:
                    touch, rec, record = device_call(touch_reference, session.client, name, e_ref, heat_s=heat,
                                                     arm_s=args.arm, settle_s=args.settle)
                except WalkError as exc:
                    raise CliError(str(exc)) from None
                chain = (rec.get("result") or {}).get("sensor_chain") or {}
                say(f"  measurement {rec['measurement_id']}: {touch.t_s.size} samples, contact at "
                    f"{chain.get('contact_t_s', float('nan')):+.2f} s from heater-on")
                touches.append(touch)
                records.append(record)
                if i < len(names):
                    continue
                # The last touch's session fits, checks itself, keeps the file on the host and installs;
                # the calibration names this device (which refuses another's).
                device_id = device_call(session.client.info).get("device_id")
                cal = _checked(args, lambda tt, k: fit_calibration(tt, probe=args.probe, min_references=k), touches,
                               [(n, refs[n]) for n in (t.name for t in touches)], records, device_id)
                write_text_atomic(args.out, cal.to_json())
                rep = device_call(install_calibration, session.client, cal, key=key)
    if args.json:
        print(cal.to_json(), end="")
    else:
        print(f"calibration {cal.sha256[:12]} for probe {cal.probe} written to {args.out} and installed "
              f"({rep['sha256'][:12]})")
        _print_calibration(cal)
    return 0


def _read_calibration_file(path):
    from edge.calibration.model import CalibrationError, ProbeCalibration  # noqa: PLC0415

    try:
        with open(path, "rb") as fh:
            return ProbeCalibration.from_json(fh.read(1 << 20))
    except OSError as exc:
        raise CliError(f"--install {path}: cannot read ({exc.strerror})") from None
    except CalibrationError as exc:
        raise CliError(f"--install {path}: {exc}") from None


def _run_install(args, cal) -> int:
    from host.calibration import install_calibration  # noqa: PLC0415
    from host.flash import load_signing_key  # noqa: PLC0415

    key = load_signing_key(args.key)   # a bad key file is refused before any connection
    with device_session(args) as session:
        rep = device_call(install_calibration, session.client, cal, key=key)
    if args.json:
        print(dumps(rep))
    else:
        print(f"calibration {rep['sha256'][:12]} (probe {rep['probe']}, {rep['created_utc']}) installed")
    return 0


def _run_show(args) -> int:
    from host.calibration import read_calibration  # noqa: PLC0415

    with device_session(args) as session:
        cal, rep = device_call(read_calibration, session.client)
    if args.json:
        print(dumps({"calibrated": rep["calibrated"], "sha256": rep["sha256"], "signed_by": rep.get("signed_by"),
                     "calibration": None if cal is None else cal.to_dict()}))
    elif cal is None:
        print("no calibration installed: measurements are flagged 'uncalibrated'")
    else:
        signer = f"signed by {rep['signed_by']}" if rep.get("signed_by") else "unsigned"
        print(f"calibration {cal.sha256[:12]} for probe {cal.probe}, {cal.created_utc}, {signer}")
        _print_calibration(cal)
    return 0


def _run_check(args) -> int:
    from edge.calibration.fit import REFERENCE_U_REL, OTHER_REFERENCE_U_REL  # noqa: PLC0415
    from edge.physics.materials import load_materials  # noqa: PLC0415
    from host.calibration import check_record  # noqa: PLC0415

    name = args.reference[0]
    m = _reference(load_materials(), name)
    with device_session(args) as session:
        rec = device_call(session.client.measure)
    res = check_record(rec, m.solid.effusivity_W_s05_m2K, REFERENCE_U_REL.get(name, OTHER_REFERENCE_U_REL))
    res["reference"] = name
    res["measurement_id"] = rec.get("measurement_id")
    if args.json:
        print(dumps(res))
    elif res["holds"] is None:
        print(f"measurement {res['measurement_id']}: no answer to judge ({res['why']})")
    else:
        verdict = "holds" if res["holds"] else "does NOT hold: recalibrate"
        cal = res.get("calibration_sha256")
        print(f"{name}: e {res['e_W_s05_m2K']:.0f} ± {res['u_e_W_s05_m2K']:.0f} against "
              f"{res['reference_e_W_s05_m2K']:.0f} ({res['deviation_rel']:+.1%}, z = {res['z']:+.2f}): "
              f"the calibration {'(none installed) ' if cal is None else cal[:12] + ' '}{verdict}")
    return 0 if res["holds"] else 1


def _reference(lib, name):
    from edge.calibration.fit import DEFAULT_REFERENCES  # noqa: PLC0415

    try:
        return lib.get(name)
    except KeyError:
        close = [n for n in lib.names if name.lower() in n][:5]
        hint = f"; did you mean {', '.join(close)}?" if close else f"; defaults: {', '.join(DEFAULT_REFERENCES)}"
        raise CliError(f"--reference {name!r} is not a library material{hint}") from None


def _print_calibration(cal) -> None:
    c = cal.chain
    u = cal.u_of
    print(f"  flux sensor sensitivity  x {1.0 / c.flux_scale:.4f} of nominal  (u {u('ln_flux_scale'):.1%})")
    print(f"  sensing depth            {c.sensing_thickness_m * 1e3:.4f} mm  (u {u('ln_sensing_thickness_m'):.1%})")
    print(f"  sensing layer k          {c.k_W_mK:.4f} W/m/K  (u {u('ln_sensing_k_W_mK'):.1%})")
    print(f"  thermocouple lag         {c.tc_tau_s * 1e3:.1f} ms  (u {u('tc_tau_s') * 1e3:.1f} ms)")
    print(f"  model-form floor on e    {cal.u_rel_floor:.1%}")
    ident = (cal.self_check or {}).get("identifiability")
    if ident:
        shrink = ", ".join(f"{n} {x:.2f}" for n, x in ident["u_over_prior"].items())
        print(f"  determined               {', '.join(ident['determined']) or 'nothing'} (u / datasheet u: {shrink})")
        corr = ident["correlations"]
        if ident["traded_off"]:
            print("  traded off               " + "; ".join(f"{k} {corr[k]:+.2f}" for k in ident["traded_off"]))
        for a in ident["advice"]:
            print(f"  to determine the rest    {a}")
    check = cal.self_check or {}
    if check:
        verdict = "passed" if check.get("passed") else "FAILED (written with --force: flagged 'forced')"
        chi2 = check.get("chi2")
        print(f"  self-check               leave-one-reference-out {verdict}: chi^2 "
              f"{'inf' if chi2 is None else format(chi2, '.1f')} over {check.get('touches')} touches "
              f"(limit {check.get('limit', float('nan')):.1f})")
    if cal.device_id:
        print(f"  for device               {cal.device_id}")
    for r in cal.references:
        errs = ", ".join(f"{x:+.1%}" for x in r.rel_errors)
        print(f"  {r.name:<12} e {r.e_W_s05_m2K:.0f}: re-measured {errs}")
    for m in (cal.self_check or {}).get("misses", []):
        z = m.get("z")
        miss = "no answer" if m.get("rel_miss") is None else f"{m['rel_miss']:+.1%} (z {z:+.1f})"
        print(f"  {m['name']:<12} without itself: {miss}")


def _fit(args):
    """``--record``/``--reference`` pairs: fit the probe's calibration and write ``--out``."""
    from edge.estimation.methods import method_class  # noqa: PLC0415
    from edge.physics.geometry import PROBES  # noqa: PLC0415
    from edge.physics.materials import load_materials  # noqa: PLC0415
    from host.atomic import write_text_atomic  # noqa: PLC0415

    if args.probe not in PROBES:
        raise CliError(f"--probe: unknown probe {args.probe!r}; shipped: {', '.join(PROBES)}")
    if len(args.record) != len(args.reference):
        raise CliError(f"give one --reference per --record ({len(args.record)} records, "
                       f"{len(args.reference)} references)")
    lib = load_materials()
    # What a calibration is follows the probe head's estimator: its sensor chain, or its flux scale.
    cal = _fit_chain(args, lib) if method_class(args.probe).sensor_chain else _fit_axi(args, lib)
    write_text_atomic(args.out, cal.to_json())
    if args.json:
        print(cal.to_json(), end="")
    else:
        print(f"calibration {cal.sha256[:12]} for probe {cal.probe} written to {args.out}")
        _print_calibration(cal)
    return cal


def _reference_records(args, lib, read):
    """(name, library material, ``read(path)``) per ``--record``/``--reference`` pair; errors name the file."""
    from host.records import RecordError, read_record_metadata  # noqa: PLC0415

    out = []
    for path, name in zip(args.record, args.reference):
        m = _reference(lib, name)
        try:
            recorded = read_record_metadata(path).get("probe")
            if recorded is not None and recorded != args.probe:
                # Another head's records would calibrate the wrong sensors: refused before reading on.
                raise CliError(f"--record {path} was taken with probe {recorded!r}, not --probe {args.probe}")
            data = read(path)
        except RecordError as exc:
            raise CliError(f"--record {exc}") from None
        out.append((name, m, data))
    return out


def _fit_chain(args, lib):
    """The paper probe: its sensor chain from records that start in air, before contact."""
    from edge.calibration.fit import ReferenceTouch, fit_calibration  # noqa: PLC0415
    from host.records import read_series, read_touch, uniform_series  # noqa: PLC0415

    def read(path):
        s = read_series(path)
        return uniform_series(s["t_s"], s["T"], s["q_W_m2"], path=path), read_touch(path, probe=args.probe)

    got = _reference_records(args, lib, read)
    touches = [ReferenceTouch(name, m.solid.effusivity_W_s05_m2K, t, T, q) for name, m, ((t, T, q), _) in got]
    records = [rec for _, _, (_, rec) in got]
    return _checked(args, lambda tt, k: fit_calibration(tt, probe=args.probe, min_references=k), touches,
                    [(name, m) for name, m, _ in got], records, _records_device_id(args))


def _fit_axi(args, lib):
    """The small-heater probe: its flux sensor's scale from records that start at heater-on (estimate's format)."""
    from edge.calibration.axi import AxiReferenceTouch, fit_flux_scale  # noqa: PLC0415
    from edge.calibration.fit import OTHER_REFERENCE_U_REL, REFERENCE_U_REL  # noqa: PLC0415
    from edge.estimation.probe_estimate import AxiEstimator  # noqa: PLC0415
    from host.cli.common import load_estimator  # noqa: PLC0415
    from host.records import read_record, read_touch  # noqa: PLC0415

    got = _reference_records(args, lib, lambda path: (read_record(path), read_touch(path, probe=args.probe)))
    touches = [AxiReferenceTouch(name, m.solid.k_W_mK, m.solid.alpha_m2_s,
                                 REFERENCE_U_REL.get(name, OTHER_REFERENCE_U_REL), t, dT, q)
               for name, m, ((t, dT, q), _) in got]
    est, _ = load_estimator(None)
    axi = AxiEstimator(est, args.probe)
    return _checked(args, lambda tt, k: fit_flux_scale(axi, tt, min_references=k), touches,
                    [(name, m) for name, m, _ in got], [rec for _, _, (_, rec) in got], _records_device_id(args))


def _records_device_id(args):
    """The device the ``--record`` files were exported from (their ``device_id`` header), or None.

    Records of two devices are two probes: refused (a calibration is one probe's)."""
    from host.records import RecordError, read_record_metadata  # noqa: PLC0415

    ids = set()
    for path in args.record:
        try:
            ids.add(read_record_metadata(path).get("device_id"))
        except RecordError as exc:
            raise CliError(f"--record {exc}") from None
    named = sorted(i for i in ids if i)
    if len(named) > 1:
        raise CliError(f"--record files come from {len(named)} devices ({', '.join(named)}): a calibration is one "
                       "probe's; give the records of one")
    return named[0] if named else None


def _checked(args, fit, touches, refs, records, device_id):
    """Fit, leave-one-reference-out self-check and re-measure through the estimate path (host.calibration)."""
    from edge.calibration.fit import OTHER_REFERENCE_U_REL, REFERENCE_U_REL  # noqa: PLC0415
    from edge.calibration.model import CalibrationError  # noqa: PLC0415
    from host.calibration import CalibrationRefused, checked_calibration, seam_remeasure  # noqa: PLC0415

    names = [n for n, _ in refs]
    e_refs = [m.solid.effusivity_W_s05_m2K for _, m in refs]
    u_refs = [REFERENCE_U_REL.get(n, OTHER_REFERENCE_U_REL) for n in names]
    remeasure = seam_remeasure(records, _contexts(records))
    try:
        cal, check = checked_calibration(fit, touches, names, e_refs, u_refs, remeasure,
                                         force=getattr(args, "force", False), device_id=device_id)
    except (CalibrationError, CalibrationRefused, ValueError) as exc:
        msg = str(exc)
        raise CliError(msg if msg.startswith("calibration") else f"calibration: {msg}") from None
    args._self_check = check
    return cal


def _contexts(records):
    """Each reference record's estimate context: the shipped bundle, its method, the default thresholds.

    The ``[measurement]`` thresholds are the defaults a device runs with.  ``thermotouch estimate``
    reads an export's ``measurement.*`` header lines over them (``host.cli.estimate._thresholds``);
    importing it here would close an import cycle (estimate imports this module's
    ``calibration_file``), so an export from a device with other thresholds may be judged
    differently here: they set the quality flags (which can withhold an answer), not the fit.
    """
    from host.cli.common import seam_context  # noqa: PLC0415

    cache = {}
    out = []
    for rec in records:
        if rec is None:
            out.append(None)
            continue
        if rec.method not in cache:
            cache[rec.method] = seam_context(None, method=rec.method)
        out.append(cache[rec.method])
    return out


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
