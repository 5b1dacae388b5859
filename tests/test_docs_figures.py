"""No stale figure in README.md and docs/ (issue #33): generated blocks have their writer, quoted constants are the code's.

Two kinds of figure can go stale without a test noticing:

* a generated block (``<!-- TAG:begin --> ... <!-- TAG:end -->``) whose bench no longer writes it
  (renamed, removed, or writing another file): its table then stays as it was typed last. Every tag
  in the docs must be written by a ``write_block``/``update_readme`` call in ``bench/*.py``, into
  the file that holds it, and every tag a bench writes must exist (else the bench dies after its
  run), once across all docs.
* a constant of the code quoted in prose (a threshold, a default, a pin): read here from the
  code and compared with the number the docs print. A quote that is reworded so that its pattern
  no longer matches fails too: re-point the pattern, do not drop it.

Figures measured by a bench are not checked here against ``bench/results``: the benches rewrite
them, and the prose should cite their block rather than retype them.
"""

from __future__ import annotations

import functools
import gc
import json
import math
import re
from pathlib import Path

import pytest

from edge.calibration.selfcheck import CHI2_ACCEPT_P
from edge.estimation.running import CHAIN_EVERY_s, ESTIMATOR_EVERY_s, REFIT_MAX_SHARE
from edge.hw.chips import CHIPS
from edge.measure.profiles import PROBE_PROFILES, PROFILES
from edge.measure.signal import MIN_HEAT_s, MIN_HEAT_SAMPLES
from edge.physics.geometry import PROBES
from edge.physics.probe import FLUX_SENSITIVITY_V_per_W_m2, HEATER_THICKNESS_m
from edge.protocol.commands import MAX_EVENT_SAMPLES
from edge.recognition.objects import DEFAULT_SPREAD_REL, DEFAULT_Z_CRIT
from edge.service.config import BoardConfig, HeaterConfig, MeasurementConfig
from edge.service.events import EVENT_PERIOD_s
from edge.storage.objects_store import MAX_SET_BYTES
from host.calibration import HEAT_s
from host.demo import REFERENCE_HEAT_s
from host.gate import BOOTSTRAP_RESAMPLES, HELDOUT_SOLIDS, HELDOUT_VOLTAGES_V, MARGINS, NOISE_SEEDS
from host.lab_metadata import MAX_CHARS
from host.lab_series import MAX_TOUCHES
from host.recognition import IN_SET_ACCEPTANCE_GOAL, MIN_ACCEPTANCE
from tests.support.static_marks import excluded_module

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]

_BEGIN = re.compile(r"^<!-- ([A-Za-z0-9_-]+):begin -->$", re.M)  # a marker on its own line, not one quoted in prose
#: A writer call's first argument: a literal tag, or the literal head of one built at run time
#: (``f"calibration-bench{suffix}"``, ``"tactile-asbuilt-bench" + (...)``).
_WRITER = re.compile(r"\b(write_block|update_readme)\(\s*(f?)(['\"])([A-Za-z0-9_-]+)(\{?)\3?(\s*\+)?")


def _rel(path: Path) -> str:
    return str(path.relative_to(ROOT))


@functools.cache
def _doc_tags() -> dict[str, list[str]]:
    """tag -> the docs holding its block (each must also hold the tag's end marker)."""
    found: dict[str, list[str]] = {}
    for path in DOCS:
        text = path.read_text(encoding="utf-8")
        for tag in _BEGIN.findall(text):
            assert f"<!-- {tag}:end -->" in text, f"{_rel(path)}: <!-- {tag}:begin --> has no end marker"
            found.setdefault(tag, []).append(_rel(path))
    return found


@functools.cache
def _writers() -> list[tuple[str, str, bool, str]]:
    """``(bench file, tag or its head, dynamic, target doc)`` of every block writer in bench/."""
    out = []
    for path in sorted((ROOT / "bench").glob("*.py")):
        if path.name == "_common.py":
            continue
        src = path.read_text(encoding="utf-8")
        for m in _WRITER.finditer(src):
            func, fprefix, _, tag, brace, plus = m.groups()
            dynamic = bool(brace and fprefix) or bool(plus)
            call = src[m.start():src.find("\n", m.end())]
            if func == "update_readme":
                target = "README.md"
            elif "SCIENCE_MD" in call:
                target = "docs/science.md"
            else:
                target = "docs/results.md"
            out.append((_rel(path), tag, dynamic, target))
    return out


def test_every_block_in_the_docs_has_its_bench():
    tags = _doc_tags()
    writers = _writers()
    assert writers, "no write_block/update_readme call found in bench/: has the writer been renamed?"
    dup = {t: where for t, where in tags.items() if len(where) > 1}
    assert not dup, f"a block tag in more than one place (write_block fills one file): {dup}"
    orphans = []
    for tag, (where,) in tags.items():
        hits = [w for w in writers if (w[1] == tag or (w[2] and tag.startswith(w[1])))]
        if not any(w[3] == where for w in hits):
            orphans.append(f"{where}: <!-- {tag} --> is written by "
                           + (", ".join(f"{w[0]} into {w[3]}" for w in hits) or "no bench"))
    assert not orphans, "generated blocks no bench writes (stale tables):\n" + "\n".join(orphans)


def test_every_block_a_bench_writes_exists():
    tags = _doc_tags()
    missing = [f"{file} writes <!-- {tag} --> into {target}" for file, tag, dynamic, target in _writers()
               if not any(t == tag or (dynamic and t.startswith(tag)) for t in tags)
               or (not dynamic and target not in tags.get(tag, [target]))]
    assert not missing, "benches write blocks the docs do not have:\n" + "\n".join(missing)


# --- constants of the code quoted in prose ---------------------------------------------------

def _quotes() -> list[tuple[str, str, float]]:
    """``(doc, pattern with one number group, the code's value)``."""
    m, b, h = MeasurementConfig(), BoardConfig(), HeaterConfig()
    mcp, ads, adc = CHIPS["mcp9600"], CHIPS["ads1115"], CHIPS["ads122c04"]
    ads_set = {s.key: s.default for s in ads.settings}
    ug, readme, ops = "docs/user-guide.md", "README.md", "docs/operations.md"
    q = [
        # the flags' table
        (ug, r"`measurement\.no_contact_e_W_s05_m2K` \((\d+(?:\.\d+)?);", m.no_contact_e_W_s05_m2K),
        (ug, r"`noise_T_K` \((\d+(?:\.\d+)?) K\)", m.noise_T_K),
        (ug, r"`noise_q_W_m2` \((\d+(?:\.\d+)?) W/m²\)", m.noise_q_W_m2),
        (ug, r"`unstable_baseline_K` \((\d+(?:\.\d+)?) K\)", m.unstable_baseline_K),
        (ug, r"`heater\.max_on_time_s`, (\d+(?:\.\d+)?) s by default", h.max_on_time_s),
        (ug, r"`measurement\.sample_rate_Hz`, (\d+(?:\.\d+)?) Hz by default", m.sample_rate_Hz),
        # measurement profiles and running decisions
        (ug, r"contact times of (\d+(?:\.\d+)?) s, \d", PROFILES["quick"].contact_time_s),
        (ug, r"contact times of [\d.]+ s, (\d+(?:\.\d+)?) s \(the paper's\)", PROFILES["standard"].contact_time_s),
        (ug, r"\(the paper's\) and (\d+(?:\.\d+)?) s at the device's", PROFILES["precise"].contact_time_s),
        (ug, r"small-heater probe has its own profile, (\d+(?:\.\d+)?) s at",
         PROBE_PROFILES["small-heater"].contact_time_s),
        (ug, r"own profile, [\d.]+ s at (\d+(?:\.\d+)?) Hz", PROBE_PROFILES["small-heater"].sample_rate_Hz),
        (ug, r"sensor chain refitted every (\d+(?:\.\d+)?) s", CHAIN_EVERY_s),
        (ug, r"estimate refitted every (\d+(?:\.\d+)?) s", ESTIMATOR_EVERY_s),
        (ug, r"more than a (fifth) of the time", REFIT_MAX_SHARE),
        # metadata, series, objects
        (ug, r"printable text, at most (\d+) characters", MAX_CHARS["sample"]),
        (ug, r"at most \d+ characters; notes (\d+)", MAX_CHARS["notes"]),
        (ug, r"`--repeat N`, 2 to (\d+)", MAX_TOUCHES),
        (ug, r"checks the size \(at most (\d+) kB\)", MAX_SET_BYTES / 1024),
        (ug, r"uses T = 1 and z_crit = (\d+(?:\.\d+)?)", DEFAULT_Z_CRIT),
        (ug, r"specimen-to-specimen spread of e, default (\d+(?:\.\d+)?)", DEFAULT_SPREAD_REL),
        # calibration
        (ug, r"it heats `--time S`, default (\d+(?:\.\d+)?) s", HEAT_s),
        (ug, r"armed (\d+(?:\.\d+)?)-s touches of pmma", REFERENCE_HEAT_s),
        (ug, r"a χ² test \(p = (\d+(?:\.\d+)?)\)", CHI2_ACCEPT_P),
    ]
    paper, small = PROBES["paper"], PROBES["small-heater"]
    sci = "docs/science.md"
    q += [  # the probe heads
        (readme, r"supported: the paper's (\d+ × \d+) mm heater", math.pi * paper.heater_radius_m ** 2 * 1e6),
        (readme, r"and a (\d+(?:\.\d+)?) mm-radius small heater", small.heater_radius_m * 1e3),
        (sci, r"A heater \((\d+ × \d+) mm, \d+ µm\)", math.pi * paper.heater_radius_m ** 2 * 1e6),
        (sci, r"A heater \(\d+ × \d+ mm, (\d+) µm\)", HEATER_THICKNESS_m * 1e6),
        (sci, r"FHF05 class, (\d+(?:\.\d+)?) µV per W/m²", FLUX_SENSITIVITY_V_per_W_m2 * 1e6),
        (sci, r"small-heater probe \((\d+(?:\.\d+)?) mm-radius heater disk", small.heater_radius_m * 1e3),
    ]
    contrib = "docs/contributing.md"
    slow_modules = sum(excluded_module(f, "not slow") for f in (ROOT / "tests").rglob("test_*.py"))
    q += [  # the device's shortest touch; the test tiers
        (ops, r"a touch shorter than max\((\d+(?:\.\d+)?) s, \d+ samples\)", MIN_HEAT_s),
        (ops, r"a touch shorter than max\([\d.]+ s, (\d+) samples\)", MIN_HEAT_SAMPLES),
        (contrib, r"neither imports nor rewrites the (\d+) modules that are slow as a whole", slow_modules),
        # tests/conftest.py sets it in every test process, this one included
        (contrib, r"garbage collector every (\d+ \d+) net allocations", gc.get_threshold()[0]),
    ]
    api, ros = "docs/python-api.md", "docs/ros.md"
    q += [  # the events a touch streams
        (api, r"a batch of raw readings, at most every (\d+(?:\.\d+)?) s", EVENT_PERIOD_s),
        (api, r"a batch of raw readings, at most every [\d.]+ s \((\d+) at most\)", MAX_EVENT_SAMPLES),
        (api, r"the running answer changed, at most every (\d+(?:\.\d+)?) s", EVENT_PERIOD_s),
        (ros, r"while the probe heats \(at most every (\d+(?:\.\d+)?) s of the touch\)", EVENT_PERIOD_s),
    ]
    res = "docs/results.md"
    q += [  # the open-set test's acceptance
        (res, r"`z_crit` is fitted so that (\d+) % of in-set touches are accepted", IN_SET_ACCEPTANCE_GOAL * 100),
        (res, r"issue #12 asks for at least (\d+) %", MIN_ACCEPTANCE * 100),
    ]
    shipped = json.loads((ROOT / "models" / "default" / "manifest.json").read_text(encoding="utf-8"))["metrics"]
    q += [  # the shipped bundle's own metrics (its manifest)
        (sci, r"on those p1 and p2 explain (\d+(?:\.\d+)?) %", round(100 * shipped["pca_explained_variance_2"], 1)),
        (sci, r"left out in turn — (\d+(?:\.\d+)?) in the shipped bundle", round(shipped["prior_rho_c_intrinsic_ln"], 2)),
        (sci, r"in the shipped bundle, where a fixed (\d+(?:\.\d+)?) covered", shipped["prior_rho_c_intrinsic_ln_before"]),
        (sci, r"by leave-one-out \((\d+(?:\.\d+)?) in ln ρc", round(shipped["prior_rho_c_intrinsic_ln"], 2)),
    ]
    heldout_e = [solid.effusivity_W_s05_m2K for _, solid in HELDOUT_SOLIDS]
    q += [  # the deploy gate's evaluation set and margins
        (ops, r"fixed and seeded: (\d+) simulated touches", (len(HELDOUT_SOLIDS) * len(HELDOUT_VOLTAGES_V) + 9)
         * len(NOISE_SEEDS)),
        (ops, r"touches, (\d+) materials that are not in the", len(HELDOUT_SOLIDS)),
        (ops, r"training library \(e from (\d+) to", round(min(heldout_e))),
        (ops, r"training library \(e from \d+ to (\d+ \d+) W", round(max(heldout_e), -2)),
        (ops, r"at (\d+)/\d+/\d+ V and the paper's three", HELDOUT_VOLTAGES_V[0]),
        (ops, r"at \d+/(\d+)/\d+ V and the paper's three", HELDOUT_VOLTAGES_V[1]),
        (ops, r"at \d+/\d+/(\d+) V and the paper's three", HELDOUT_VOLTAGES_V[2]),
        (ops, r"samples at their voltages, (\d+) noise seeds each", len(NOISE_SEEDS)),
        (ops, r"seeded paired bootstrap \((\d+) resamples", BOOTSTRAP_RESAMPLES),
        (ops, r"practical margin \((\d+) points of relative e", MARGINS["paper_e"] * 100),
        (ops, r"relative e; (\d+(?:\.\d+)?) in ln k", MARGINS["paper_k_vs_prior"]),
        (ops, r"in ln k; (\d+(?:\.\d+)?) in ln e\)", MARGINS["name_e"]),
    ]
    for doc in (readme, ops):  # the wiring table, twice
        q += [
            (doc, r"MCP9600 thermocouple converter \| I2C-1 \(GPIO2 SDA / GPIO3 SCL\), address (0x[0-9A-Fa-f]+)",
             mcp.default_address),
            (doc, r"address 0x60 \(0x60–(0x[0-9A-Fa-f]+)\)", max(mcp.addresses)),
            (doc, r"ADS1115 \(heat-flux sensor on AIN0–AIN1\) \| I2C-1, address (0x[0-9A-Fa-f]+)",
             ads.default_address),
            (doc, r"address 0x48 \(0x48–(0x[0-9A-Fa-f]+)\)", max(ads.addresses)),
            (doc, r"address 0x48 \(0x48–0x4B\), ±(\d+(?:\.\d+)?) V", ads_set["fsr_V"]),
            (doc, r"±0\.256 V, (\d+) SPS", ads_set["data_rate_sps"]),
            (doc, r"flux on AIN2–AIN3\) \| I2C-1, address (0x[0-9A-Fa-f]+)", adc.default_address),
            (doc, r"heater enable \| GPIO(\d+) ", b.heater_enable_offset),
            (doc, r"`/dev/gpiochip0` line (\d+)\)", b.heater_enable_offset),
            (doc, r"trigger button \| GPIO(\d+) ", b.trigger_offset),
            (doc, r"GPIO18[^|]*, (\d+(?:\.\d+)?) ms period", h.pwm_period_ns / 1e6),
        ]
    return q


def _number(text: str) -> float:
    words = {"fifth": 0.2, "quarter": 0.25, "half": 0.5, "third": 1 / 3}
    if text in words:
        return words[text]
    if "×" in text:  # a rectangle's sides: its area
        return math.prod(float(x) for x in text.split("×"))
    return float(int(text, 16)) if text.lower().startswith("0x") else float(text.replace(" ", ""))


def test_quoted_constants_are_the_codes():
    texts = {_rel(p): re.sub(r"\s+", " ", p.read_text(encoding="utf-8")) for p in DOCS}
    wrong = []
    for doc, pattern, value in _quotes():
        found = re.findall(pattern, texts[doc])
        if not found:
            wrong.append(f"{doc}: /{pattern}/ no longer matches (re-point the pattern to the quote)")
            continue
        bad = [f for f in found if _number(f) != pytest.approx(float(value), rel=1e-9)]
        if bad:
            wrong.append(f"{doc}: /{pattern}/ prints {bad}, the code says {value}")
    assert not wrong, "quoted constants differ from the code:\n" + "\n".join(wrong)


def test_the_results_index_names_each_blocks_bench():
    """docs/results.md's table of blocks lists every block of the file with a command of the bench that writes it."""
    text = (ROOT / "docs" / "results.md").read_text(encoding="utf-8")
    rows = dict(re.findall(r"^\| `([A-Za-z0-9_-]+)` \| `python (bench/\w+\.py[^`]*)` \|$", text, re.M))
    in_file = {t for t, where in _doc_tags().items() if where == ["docs/results.md"]}
    assert set(rows) == in_file, (f"index without a block: {sorted(set(rows) - in_file)}; "
                                  f"blocks missing from the index: {sorted(in_file - set(rows))}")
    wrong = []
    for tag, cmd in rows.items():
        script, *args = cmd.split()
        writers = [w for w in _writers() if w[0] == script and (w[1] == tag or (w[2] and tag.startswith(w[1])))]
        if not writers:
            wrong.append(f"{tag}: {script} does not write it")
            continue
        src = (ROOT / script).read_text(encoding="utf-8")
        wrong += [f"{tag}: {script} has no option {a}" for a in args
                  if a.startswith("--") and f'"{a}"' not in src]
    assert not wrong, "\n".join(wrong)


def test_every_bench_command_in_the_docs_names_a_bench_and_its_options():
    """``python bench/NAME.py --opt ...`` in the docs: the script exists and has each option it is shown with."""
    wrong, seen = [], 0
    for path in DOCS:
        for m in re.finditer(r"python (bench/\w+\.py)([^`\n]*)", path.read_text(encoding="utf-8")):
            seen += 1
            script = ROOT / m.group(1)
            if not script.exists():
                wrong.append(f"{_rel(path)}: {m.group(1)} does not exist")
                continue
            src = script.read_text(encoding="utf-8")
            wrong += [f"{_rel(path)}: {m.group(1)} has no option {opt}"
                      for opt in re.findall(r"(?<![\w-])(--[\w-]+)", m.group(2))
                      if f'"{opt}"' not in src and f"'{opt}'" not in src]
    assert seen >= 50, f"only {seen} bench commands found in the docs: has the pattern gone stale?"
    assert not wrong, "\n".join(wrong)
