"""``thermotouch report``: a measurement report of a series, or a calibration certificate (plain HTML).

::

    thermotouch report SERIES.json --out REPORT.html [--pdf REPORT.pdf]
    thermotouch report --calibration CAL.json --out CERT.html [--pdf CERT.pdf] [--operator NAME] [--notes TEXT]

The report (:mod:`host.lab_report`) reads a file ``thermotouch series``
wrote; the certificate (:mod:`host.lab_certificate`) a calibration
``thermotouch calibrate`` wrote (checked like the device checks it; the
datasheet probe's "calibration", ``calibrated: false``, is refused: there is
nothing to certify).  ``--operator``/``--notes`` say who issues a certificate
(a series file carries its own metadata).  One file, no external assets; an
existing ``--out`` is replaced only with ``--overwrite``.  A bad input file
is one line, exit 2.  The report draws each answered touch with the shared
touch figure (:mod:`host.lab_plots`; the representative touch above
:data:`host.lab_plots.MAX_TOUCH_FIGURES`).  ``--pdf`` also writes the same
content as A4 pages (:mod:`host.lab_pdf`, Matplotlib's PDF writer).
"""

from __future__ import annotations

from host.cli.args import add_output, existing_file
from host.cli.errors import EXIT_RUNTIME, CliError
from host.lab_metadata import add_metadata_args


def add_parser(sub, parents):
    p = sub.add_parser("report", help="HTML measurement report of a series, or a calibration certificate",
                       parents=parents)
    p.add_argument("series", nargs="?", type=existing_file, default=None, metavar="SERIES.json",
                   help="series file written by thermotouch series --out")
    p.add_argument("--calibration", type=existing_file, default=None, metavar="CAL.json",
                   help="write the calibration certificate of this calibration file (thermotouch calibrate --out)")
    add_metadata_args(p, fields=("operator", "notes"),
                      helps={"operator": "with --calibration: who issues the certificate",
                             "notes": "with --calibration: notes printed on the certificate"})
    add_output(p, "--out", suffixes=(".html", ".htm"), metavar="REPORT.html", required=True,
               help="HTML file to write")
    add_output(p, "--pdf", suffixes=(".pdf",), metavar="REPORT.pdf", default=None,
               help="also write the same content as a PDF (A4 pages: text, tables, figures)")
    p.set_defaults(func=run)


def _read_calibration(path):
    from edge.calibration.model import CalibrationError, ProbeCalibration  # noqa: PLC0415

    try:
        raw = open(path, "rb").read()
    except OSError as exc:
        raise CliError(f"{path}: cannot read: {exc.strerror or exc}") from None
    try:
        cal = ProbeCalibration.from_json(raw)
    except CalibrationError as exc:
        raise CliError(f"{path}: not a usable calibration: {exc}") from None
    if not cal.calibrated:
        raise CliError(f"{path}: the uncalibrated datasheet probe (calibrated: false): nothing to certify")
    return cal


def run(args) -> int:
    from host.atomic import write_text_atomic  # noqa: PLC0415
    from host.lab_series import SeriesFileError, load_series, software_version, utc_now  # noqa: PLC0415

    if (args.series is None) == (args.calibration is None):
        raise CliError("give a series file (SERIES.json) or --calibration CAL.json, not both")
    if args.pdf is not None and args.pdf.resolve() == args.out.resolve():
        raise CliError("--pdf and --out name the same file")
    now, ver = utc_now(), software_version()
    if args.calibration is not None:
        from host.lab_certificate import certificate_blocks, certificate_html, certificate_parts  # noqa: PLC0415

        cal = _read_calibration(args.calibration)
        parts = certificate_parts(cal, source_name=args.calibration.name, generated_utc=now, software_version=ver,
                                  issued_by=args.operator, notes=args.notes)
        text = certificate_html(cal, source_name=args.calibration.name, generated_utc=now, software_version=ver,
                                parts=parts)
        title, blocks = parts["title"], (lambda: certificate_blocks(parts))
        footer = f"calibration {cal.sha256[:12]}"
        what = f"calibration certificate of probe {cal.probe} ({cal.sha256[:12]})"
    else:
        if args.operator is not None or args.notes is not None:
            raise CliError("--operator and --notes are for a certificate (--calibration); a series file carries "
                           "its own (thermotouch series --operator ... --notes ...)")
        from host.lab_report import (report_blocks, report_title, series_plot_png, series_report_html,  # noqa: PLC0415
                                     touch_figures)

        try:
            doc = load_series(args.series)
        except SeriesFileError as exc:
            raise CliError(f"{args.series}: {exc}") from None
        # Drawn once: the HTML and the PDF show the same PNGs (the summary plot was drawn for each, 0.1 s).
        figures, summary_png = touch_figures(doc), series_plot_png(doc)
        text = series_report_html(doc, source_name=args.series.name, generated_utc=now, software_version=ver,
                                  figures=figures, summary_png=summary_png)
        title = report_title(doc)
        blocks = (lambda: report_blocks(doc, source_name=args.series.name, generated_utc=now,
                                        software_version=ver, figures=figures, summary_png=summary_png))
        footer = f"series {args.series.name}"
        s = doc["summary"]
        what = f"measurement report of {s['n_requested']} touches ({s['n_answered']} answered)"
    try:
        write_text_atomic(args.out, text)
    except OSError as exc:
        raise CliError(f"cannot write {args.out}: {exc.strerror or exc}", EXIT_RUNTIME) from None
    print(f"{what}: {args.out}")
    if args.pdf is not None:
        from host.lab_pdf import layout_pages, write_pdf  # noqa: PLC0415

        pages = layout_pages(title, blocks(), footer)
        try:
            write_pdf(args.pdf, pages, title=title)
        except OSError as exc:
            raise CliError(f"{args.out} written, but cannot write {args.pdf}: {exc.strerror or exc}",
                           EXIT_RUNTIME) from None
        print(f"PDF ({len(pages)} pages): {args.pdf}")
    return 0
