"""A lab's paperwork from a simulated run: calibration walk-through, a series, the report and the certificate.

On one simulated probe (scene ``alu_20V_faithful``: the faithful axisymmetric world, an as-built
paper probe on the precision board, its storage in a temporary ``--workdir``):

1. ``thermotouch calibrate --sim ... --out cal.json`` -- the walk-through on pmma, pyroceram and
   AISI 304; the calibration is installed on that probe;
2. ``thermotouch series --sim ... --repeat 5`` -- five touches of the scene's aluminium block with
   sample, lot, operator and notes; the calibrated sensor chain answers;
3. ``thermotouch report series.json --out report.html --pdf report.pdf`` -- the measurement report
   (each touch drawn with the shared touch figure);
4. ``thermotouch report --calibration cal.json --out certificate.html --pdf certificate.pdf``.

Then page 1 of the report and of the certificate is rendered by the PDF's own page code
(:func:`host.lab_pdf.layout_pages`) into docs/img/report.png and docs/img/certificate.png, the
README's pictures.  Each step's wall time and the outputs' sizes and page counts go to
bench/results/report.json.

Run:  python bench/report_bench.py [--keep DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _common import ROOT, write_json

SCENE = "alu_20V_faithful"
TOUCHES = 5
IMG = ROOT / "docs" / "img"


def _run(*argv: str) -> tuple[float, str]:
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-m", "host.cli.main", *argv], env=dict(os.environ, PYTHONPATH=str(ROOT)),
                         capture_output=True, text=True, timeout=900, cwd=ROOT)
    wall = time.perf_counter() - t0
    if out.returncode != 0:
        raise SystemExit(f"thermotouch {' '.join(argv)} failed ({out.returncode}):\n{out.stderr}")
    return wall, out.stdout


def _pdf_pages(path: Path) -> int:
    return len(re.findall(rb"/Type /Page\b", path.read_bytes()))


def _page1_pngs(series: Path, cal: Path) -> dict:
    """Page 1 of each document, through the same layout code the PDF uses."""
    sys.path.insert(0, str(ROOT))
    from edge.calibration.model import ProbeCalibration  # noqa: PLC0415
    from host.lab_certificate import certificate_blocks, certificate_parts  # noqa: PLC0415
    from host.lab_pdf import layout_pages, page_png  # noqa: PLC0415
    from host.lab_report import report_blocks, report_title, touch_figures  # noqa: PLC0415
    from host.lab_series import load_series, software_version, utc_now  # noqa: PLC0415

    import matplotlib.pyplot as plt  # noqa: PLC0415

    IMG.mkdir(parents=True, exist_ok=True)
    now, ver = utc_now(), software_version()
    doc = load_series(series)
    pages = layout_pages(report_title(doc), report_blocks(doc, source_name=series.name, generated_utc=now,
                                                          software_version=ver, figures=touch_figures(doc)),
                         f"series {series.name}")
    (IMG / "report.png").write_bytes(page_png(pages[0]))
    n_report = len(pages)
    for f in pages:
        plt.close(f)
    c = ProbeCalibration.from_json(cal.read_bytes())
    parts = certificate_parts(c, source_name=cal.name, generated_utc=now, software_version=ver,
                              issued_by="report bench (simulated)")
    pages = layout_pages(parts["title"], certificate_blocks(parts), f"calibration {c.sha256[:12]}")
    (IMG / "certificate.png").write_bytes(page_png(pages[0]))
    for f in pages:
        plt.close(f)
    return {"report_pages_laid_out": n_report, "report_png_bytes": (IMG / "report.png").stat().st_size,
            "certificate_png_bytes": (IMG / "certificate.png").stat().st_size}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--keep", type=Path, default=None, help="write the run's files here (a new directory)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="report-bench-") as tmp:
        d = args.keep or Path(tmp)
        d.mkdir(parents=True, exist_ok=args.keep is None)
        work, cal, series = d / "probe", d / "cal.json", d / "series.json"
        times = {}
        times["calibrate_s"], text = _run("calibrate", "--sim", SCENE, "--workdir", str(work), "--out", str(cal))
        print(text.strip().splitlines()[0] if text.strip() else "", flush=True)
        times["series_s"], text = _run("series", "--sim", SCENE, "--workdir", str(work), "--repeat", str(TOUCHES),
                                       "--sample", "Aluminium block A-7 (simulated)", "--lot", "SIM-2026-11",
                                       "--operator", "report bench", "--notes", "dry contact, 2 s touches",
                                       "--out", str(series))
        print(text, flush=True)
        times["report_s"], text = _run("report", str(series), "--out", str(d / "report.html"),
                                       "--pdf", str(d / "report.pdf"))
        print(text, end="", flush=True)
        times["certificate_s"], text = _run("report", "--calibration", str(cal), "--operator",
                                            "report bench (simulated)", "--out", str(d / "certificate.html"),
                                            "--pdf", str(d / "certificate.pdf"))
        print(text, end="", flush=True)
        doc = json.loads(series.read_text())
        e = doc["summary"]["quantities"]["effusivity_W_s05_m2K"]
        html = (d / "report.html").read_text()
        result = {
            "scene": SCENE, "touches": TOUCHES, "answered": doc["summary"]["n_answered"],
            "methods": sorted({t["answer"]["method"] for t in doc["touches"] if t["answer"]}),
            "e_mean_W_s05_m2K": e["mean"], "e_rsd": e["rsd"], "e_u_mean_W_s05_m2K": e["u_mean"],
            "e_verdict": e["verdict"], "wall_s": times,
            "series_bytes": series.stat().st_size, "report_html_bytes": len(html.encode()),
            "report_pngs": html.count("data:image/png;base64,"),
            "report_pdf_pages": _pdf_pages(d / "report.pdf"),
            "certificate_pdf_pages": _pdf_pages(d / "certificate.pdf"),
        }
        result.update(_page1_pngs(series, cal))
    path = write_json("report", result)
    print(json.dumps({k: v for k, v in result.items()}, indent=1))
    print(f"wrote {path}, {IMG / 'report.png'}, {IMG / 'certificate.png'}")


if __name__ == "__main__":
    main()
