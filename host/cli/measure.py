"""``thermotouch measure``: one touch -- e, k and alpha with uncertainties, the material, flags; optionally a plot."""

from __future__ import annotations

from host.cli.args import add_device_args, add_output
from host.cli.args import measure_bound as _protocol_bound
from host.cli.common import device_session
from host.cli.errors import EXIT_RUNTIME, CliError
from host.cli.report import dumps, measure_json, print_result
from host.lab_metadata import add_metadata_args, metadata_of

#: Plot formats (the suffix picks one).
PLOT_SUFFIXES = (".png", ".pdf", ".svg")




def add_parser(sub, parents):
    p = sub.add_parser("measure", help="one touch: e, k and alpha with uncertainties, material, flags",
                       parents=parents)
    add_device_args(p)
    power = p.add_mutually_exclusive_group()
    conv, rng = _protocol_bound("voltage_V")
    power.add_argument("--voltage", type=conv, help=f"heater voltage, V ({rng})")
    conv, rng = _protocol_bound("power_W")
    power.add_argument("--power", type=conv, help=f"heater power, W ({rng})")
    timing = p.add_mutually_exclusive_group()
    conv, rng = _protocol_bound("contact_time_s")
    timing.add_argument("--time", type=conv, help=f"contact (heating) time, s ({rng})")
    timing.add_argument("--profile", choices=("quick", "standard", "precise"),
                        help="contact time of a measurement profile: quick 0.5 s, standard 2 s, precise 4 s "
                             "(accuracy per profile: docs/results.md, estimation tables)")
    p.add_argument("--until-decided", action="store_true",
                   help="stop heating as soon as the running answer's posterior reaches the device's "
                        "measurement.decide_posterior (at most the contact time); prints the answer and when")
    conv, rng = _protocol_bound("arm_s")
    p.add_argument("--arm", type=conv, metavar="S", default=None,
                   help=f"armed: the device samples in air up to S seconds for the touch, finds the contact from "
                        f"its sensors and heats --settle seconds after it ({rng}; 0 = off)")
    conv, rng = _protocol_bound("settle_s")
    p.add_argument("--settle", type=conv, metavar="S", default=None,
                   help=f"armed: detected contact to heater-on, s ({rng}; default the device's)")
    p.add_argument("--method", choices=("paper", "default"), default=None,
                   help="estimation method for this touch (default: the device's setting)")
    add_metadata_args(p)
    p.add_argument("--stream", action="store_true",
                   help="print the touch's phases and running answers as the device pushes them "
                        "(with --json: one JSON object per line, the answer last)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    add_output(p, "--plot", suffixes=PLOT_SUFFIXES, metavar="FILE.png",
               help="save measured and fitted flux and temperature (.png, .pdf or .svg; in an existing directory)")
    p.add_argument("--bundle", metavar="DIR", default=None,
                   help="with --plot: the device's model bundle, for the fitted curves (default: the shipped "
                        "bundle when the device runs it)")
    p.set_defaults(func=run)


def run(args) -> int:
    from host.progress import Ticker  # noqa: PLC0415
    from host.touch import touch  # noqa: PLC0415

    rate = None
    if args.profile is not None:
        from edge.measure.profiles import PROFILES  # noqa: PLC0415

        args.time = PROFILES[args.profile].contact_time_s
        rate = PROFILES[args.profile].sample_rate_Hz
    if args.bundle is not None:
        from host.touch import bundle_identity  # noqa: PLC0415

        if not args.plot:
            raise CliError("--bundle is for the fitted curves of --plot")
        bundle_identity(args.bundle)  # a wrong directory is refused before the touch
    on_event = _event_printer(args.json) if args.stream else None
    if args.plot:
        from host.plots import preload  # noqa: PLC0415

        preload()  # Matplotlib's import (most of a plot's time) while the touch runs
    cal = None
    with device_session(args) as session:
        with Ticker("measuring", enabled=not (args.json or args.stream)):
            t = touch(session, power_W=args.power, voltage_V=args.voltage, contact_time_s=args.time,
                      method=args.method, with_series=bool(args.plot), bundle_dir=args.bundle,
                      sample_rate_Hz=rate, until_decided=args.until_decided, arm_s=args.arm,
                      settle_s=args.settle, on_event=on_event)
        if args.plot and (t.record.get("result") or {}).get("method") == "sensor_chain":
            from host.calibration import read_calibration  # noqa: PLC0415

            cal = read_calibration(session.client)[0]  # the chain's answer is drawn with its own curve
        # The title identifies the measurement; a label names the sample or the scene, never the port.
        label = metadata_of(args).get("sample") or (session.simulator.scene.name if session.simulated else "")
    d = measure_json(t.record)
    decision = (t.record.get("result") or {}).get("decision")
    if decision is not None:
        d["decision"] = decision
    metadata = metadata_of(args)
    if any(v is not None for v in metadata.values()):  # the user's words about the sample, carried as given
        d["metadata"] = metadata
    fit = t.fits.get(d["method"])
    only_measured = "" if fit is not None or cal is not None else \
        f" (measured series only: {t.fit_note or 'no model fit'})"
    # The result is printed first: a plot that cannot be written must not lose it.
    if args.json:
        print(dumps(d), flush=True)
    else:
        print(f"measurement {d['measurement_id']}: {d['power_W']:.3g} W for {d['contact_time_s']:.3g} s")
        if "metadata" in d:
            print("  ".join(f"{k} {v}" for k, v in d["metadata"].items() if v is not None))
        print_result(d)
        if decision is not None:
            how = "decided" if decision.get("stopped_early") else "not decided, full contact time"
            print(f"running answer: {decision.get('object')} (posterior {decision.get('posterior', 0):.3f}) "
                  f"at {decision.get('elapsed_s', 0):.2f} s: {how}")
    if args.plot:
        from host.plot_data import touch_identity  # noqa: PLC0415
        from host.plots import plot_touch  # noqa: PLC0415

        try:
            plot_touch(args.plot, t.series, {**d, **touch_identity(t.record)}, fit, label + only_measured,
                       calibration=cal)
        except (OSError, ValueError) as exc:
            why = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
            raise CliError(f"measurement {d['measurement_id']} done, but cannot write the plot {args.plot}: {why}",
                           EXIT_RUNTIME) from None
        if not args.json:
            print(f"plot: {args.plot}{only_measured}")
    if d.get("effusivity_W_s05_m2K") is None:  # the device touched but gave no estimate: not a success
        raise CliError(f"measurement {d['measurement_id']} gave no estimate"
                       + (f" (flags: {', '.join(d['flags'])})" if d["flags"] else ""), EXIT_RUNTIME)
    return 0


def _event_printer(as_json: bool):
    """An ``on_event`` for :func:`host.touch.touch` printing what a robot or a user watches live.

    Sample batches are not printed as text (they are the stored series, read with ``history
    --export-series``); with ``--json`` every event is one line, so a pipe sees the samples too.
    """
    from dataclasses import asdict  # noqa: PLC0415

    from host.api import Phase, RunningAnswer, typed_event  # noqa: PLC0415

    def on_event(event) -> None:
        item = typed_event(event)
        if as_json:
            print(dumps({"event": type(item).__name__.lower(), **asdict(item)}), flush=True)
        elif isinstance(item, Phase):
            print(f"  {item.t_s:6.2f} s  {item.phase}"
                  + (f" ({item.events_dropped} events lost on the link)" if item.events_dropped else ""),
                  flush=True)
        elif isinstance(item, RunningAnswer):
            print(f"  {item.t_s:6.2f} s  running answer: {item.object} (posterior {item.posterior:.2f}), "
                  f"e {item.effusivity_W_s05_m2K:.4g} ± {100 * item.u_ln_e:.2g} %"
                  + (", decided" if item.decided else ""), flush=True)
    return on_event
