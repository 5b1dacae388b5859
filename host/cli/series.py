"""``thermotouch series``: N touches of one sample -- each answer, then mean, sd, RSD and the spread against u.

::

    thermotouch series --sim glass_15V --repeat 10 --sample "Borofloat <B33>" --lot L-17 \\
        --operator "A. Smith" --notes "dry contact" --out glass.json

prints every touch as it comes, then per quantity (e, k, alpha) the mean, the
sample standard deviation, the RSD, the mean stated u (k = 1) and whether the
spread agrees with it (:mod:`host.lab_stats`: chi-square of the touches about
their u-weighted mean, two-sided at 95 %, and sd / rms(u) with its accepted
band).  Touches without an answer are counted and named.  On a port, with a
terminal on stdin, each touch waits for Enter (put the probe on the sample
first); ``--cooldown`` rests the probe between touches.  ``--out`` gets the
self-describing series file (:mod:`host.lab_series`; with each answered
touch's series and fitted curve, :mod:`host.lab_plots`) that ``thermotouch
report`` turns into a measurement report; an existing file is replaced only
with ``--overwrite``.  Exit 0 when at least one touch answered, 1 when none
did (the file is still written: it records what happened).
"""

from __future__ import annotations

import argparse
import contextlib
import sys

from host.cli.args import add_device_args, add_output, bounded_float, measure_bound
from host.cli.common import device_call, device_session
from host.cli.errors import EXIT_RUNTIME, CliError
from host.cli.report import dumps, measure_json, pm
from host.lab_metadata import add_metadata_args, metadata_of
from host.lab_series import MAX_TOUCHES
from host.lab_stats import QUANTITIES, verdict_text

#: Longest rest between touches, s (an hour: longer is two sessions).
MAX_COOLDOWN_s = 3600.0


def repeat_count(text: str) -> int:
    """``--repeat``: a whole number of touches, 2 .. MAX_TOUCHES (one touch has no spread)."""
    try:
        n = int(text, 10)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number of touches, got {text!r}") from None
    if not 2 <= n <= MAX_TOUCHES:
        raise argparse.ArgumentTypeError(f"must be between 2 and {MAX_TOUCHES} touches, got {text!r}")
    return n


def add_parser(sub, parents):
    p = sub.add_parser("series", help="N touches of one sample: each answer, mean ± RSD, spread against the stated u",
                       parents=parents)
    add_device_args(p)
    p.add_argument("--repeat", type=repeat_count, required=True, metavar="N",
                   help=f"number of touches (2..{MAX_TOUCHES}; a lab reports >= 10)")
    power = p.add_mutually_exclusive_group()
    conv, rng = measure_bound("voltage_V")
    power.add_argument("--voltage", type=conv, help=f"heater voltage, V ({rng}; default the device's)")
    conv, rng = measure_bound("power_W")
    power.add_argument("--power", type=conv, help=f"heater power, W ({rng}; default the device's)")
    conv, rng = measure_bound("contact_time_s")
    p.add_argument("--time", type=conv, help=f"contact (heating) time of each touch, s ({rng})")
    p.add_argument("--cooldown", type=bounded_float(0.0, MAX_COOLDOWN_s), default=0.0, metavar="S",
                   help="rest between touches, s (on a port the host waits; on --sim the simulated clock moves "
                        f"on; 0..{MAX_COOLDOWN_s:g}, default 0)")
    add_metadata_args(p)
    add_output(p, "--out", suffixes=(".json",), metavar="SERIES.json", required=True,
               help="series file to write (every touch, metadata, device, summary; input of thermotouch report)")
    p.add_argument("--json", action="store_true", help="print the series file's content as one JSON object")
    p.set_defaults(func=run)


def touch_line(entry: dict, n: int) -> str:
    """One printed line per touch."""
    head = f"touch {entry['index']}/{n} (measurement {entry['measurement_id']})"
    if not entry["answered"]:
        return f"{head}: no answer: {entry['no_answer']}"
    a = entry["answer"]
    return (f"{head}: e {pm(a['effusivity_W_s05_m2K'], a.get('effusivity_W_s05_m2K_u'), 'W s^0.5/m^2/K')}, "
            f"k {pm(a.get('k_W_mK'), a.get('k_W_mK_u'), 'W/m/K')}, "
            f"alpha {pm(a.get('alpha_m2_s'), a.get('alpha_m2_s_u'), 'mm^2/s', 1e6)}; "
            f"flags: {', '.join(entry['flags']) or 'none'}")


def _g(v, scale=1.0) -> str:
    return "n/a" if v is None else f"{v * scale:.4g}"


def summary_lines(summary: dict) -> list[str]:
    """The printed summary: per quantity mean, sd, RSD, mean u and the verdict; then the touches without answer."""
    lines = [f"{summary['n_answered']} of {summary['n_requested']} touches answered"]
    for key, _, label, unit, scale in QUANTITIES:
        s = summary["quantities"][key]
        if not s["n"]:
            lines.append(f"{label}: no values")
            continue
        rsd = "n/a" if s["rsd"] is None else f"{s['rsd'] * 100:.2f} %"
        src = ", ".join(f"{k} {v}" for k, v in sorted(s["determined_by"].items()))
        lines.append(f"{label}: mean {_g(s['mean'], scale)} {unit}, sd {_g(s['sd'], scale)}, RSD {rsd}, "
                     f"n {s['n']}; mean stated u (k = 1) {_g(s['u_mean'], scale)}; from: {src}")
        lines.append(f"  {verdict_text(s)}")
    if summary["n_unanswered"]:
        named = "; ".join(f"touch {u['index']} (measurement {u['measurement_id']}): {u['why']}"
                          for u in summary["unanswered"])
        lines.append(f"without an answer: {summary['n_unanswered']} of {summary['n_requested']}: {named}")
    return lines


def _answer(rec: dict) -> dict:
    """A touch's answer as ``measure --json`` prints it (its running decision included)."""
    d = measure_json(rec)
    if rec["result"].get("decision") is not None:
        d["decision"] = rec["result"]["decision"]
    return d


def run(args) -> int:
    from host.atomic import write_text_atomic  # noqa: PLC0415
    from host.calibration import read_calibration  # noqa: PLC0415
    from host.lab_plots import touch_plot_inputs  # noqa: PLC0415
    from host.lab_series import run_series, series_document, software_version, utc_now  # noqa: PLC0415

    metadata = metadata_of(args)
    started = utc_now()
    n = args.repeat

    entries: list[dict] = []
    device: dict = {}
    settings = {"repeat": n, "voltage_V": args.voltage, "power_W": args.power, "contact_time_s": args.time,
                "cooldown_s": args.cooldown}

    def show(entry: dict) -> None:
        entries.append(entry)
        if not args.json:
            print(touch_line(entry, n), flush=True)

    def prompt(i: int) -> None:
        # A person holds a probe on a port: each touch waits for them (as calibrate's walk-through does).
        try:
            input(f"touch {i}/{n}: put the probe on the sample and press Enter ... ")
        except EOFError:
            raise CliError(f"stopped before touch {i}: no Enter (end of input)", EXIT_RUNTIME) from None

    calibration: list[str | None] = [None]

    def document() -> dict:
        return series_document(entries, metadata=metadata, device=device, settings=settings, started_utc=started,
                               software_version=software_version(), calibration=calibration[0])

    try:
        with device_session(args) as session:
            device.update(source="sim" if session.simulated else "port",
                          scene=session.simulator.scene.name if session.simulated else None,
                          port=None if session.simulated else session.port)
            device.update(device_call(session.client.info))
            if device.get("calibrated"):
                # Kept in the file: the report draws a sensor-chain answer with the chain's own curve.
                calibration[0] = device_call(lambda: read_calibration(session.client))[1].get("calibration")

            def plot_of(rec: dict) -> dict | None:
                return device_call(lambda: touch_plot_inputs(session, rec))

            interactive = not session.simulated and not args.json and sys.stdin.isatty()
            run_series(session, n, voltage_V=args.voltage, power_W=args.power, contact_time_s=args.time,
                       cooldown_s=args.cooldown, answer_of=_answer, plot_of=plot_of, before_touch=prompt if interactive else None,
                       on_touch=show)
    except BaseException as exc:
        # Ctrl-C or a lost probe after some touches: keep what was measured (the error is still reported).
        if entries:
            settings["stopped_after"] = len(entries)
            settings["stopped_because"] = type(exc).__name__ if not str(exc) else str(exc)
            with contextlib.suppress(OSError):
                write_text_atomic(args.out, dumps(document()) + "\n")
                if not args.json:
                    print(f"stopped after {len(entries)} of {n} touches; what was measured: {args.out}", flush=True)
        raise
    doc = document()
    text = dumps(doc)
    if args.json:
        print(text, flush=True)
    else:
        print("\n".join(summary_lines(doc["summary"])), flush=True)
    try:
        write_text_atomic(args.out, text + "\n")
    except OSError as exc:
        raise CliError(f"{n} touches done, but cannot write {args.out}: {exc.strerror or exc}", EXIT_RUNTIME) \
            from None
    if not args.json:
        print(f"series: {args.out}")
    if not doc["summary"]["n_answered"]:
        raise CliError(f"none of the {n} touches gave an answer (series written to {args.out})", EXIT_RUNTIME)
    return 0
