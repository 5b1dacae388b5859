"""Growing the tactile as-built bench: more specimens on the same probes, or more drawn probes.

Shared by bench/tactile_asbuilt_bench.py (its ``--extend``, ``--add-probes``, ``--merge-probes`` and
``--reuse``).  Every cache file is a :func:`_asbuilt_touches.save_records` npz beside the first
pass's ``tactile_asbuilt_<head>.npz``:

* ``<stem>_ext.npz``: touches only, added by ``--extend N`` on the first pass's drawn probes (their
  references, hence their calibrations, stay in the first pass's file);
* ``<stem>_probes<a>-<b>[_part<i>of<n>].npz``: newly drawn probes ``a..b`` (draw seed = probe
  number, as the first pass's), each with its own reference touches (calibrated exactly as the
  first pass's probes, by bench/tactile_asbuilt_bench.estimate_head) and ``K`` touches of every
  object.  ``--part i/n`` takes every n-th new probe so that parts run in parallel processes;
  ``--merge-probes`` joins the parts into one file.  Saved after each object, so a killed run
  loses at most one object's touches; :func:`load_all` keeps only the probes whose every object
  was touched (a probe cut short would weigh its finished objects more than the others).

Why probes and not only specimens: the ECE interval over probes and touches resamples probes, and
with three of them the probe level is coarse (issue #37).
"""

from __future__ import annotations

import re
import sys
import time
from collections import Counter

import numpy as np

import _asbuilt_touches as A

#: Seed offset of the touches an ``--extend`` pass adds: their specimens, hands and scene seeds are
#: independent of the first pass's (``100 * i + j + 1``, j < 100) so the old records stay valid.
EXTEND_SEED = 100_000
#: Seed offset of the touches on an ``--add-probes`` probe ``p``: ``PROBES_SEED + 10_000 p + 100 i + k``
#: (object ``i``, touch ``k`` < 100), clear of the first pass's and the extension's scene seeds.
PROBES_SEED = 200_000
#: A new probe's touch ``k`` of an object carries ``j = PROBE_J * p + k``: unique per object across
#: probes (the until-decided emulation keys a touch by (object, j)).
PROBE_J = 1000


def record_keys(meta) -> list[tuple]:
    """One key per record of one cache file: (probe, kind, name, j).

    A reference touch carries no ``j`` and each reference is touched more than once
    (:data:`_objects.REFERENCES`: two hands per material): its key is its order among the same
    probe's touches of that material in the file.  Keyed by name alone, a merge kept the first touch
    of each material and dropped the second (probes 4-63 were calibrated on 3 touches, not 6).
    """
    seen: Counter = Counter()
    out = []
    for m in meta:
        j = m.get("j")
        if m["kind"] == "reference" and j is None:
            j = seen[(m["probe"], m["name"])]
            seen[(m["probe"], m["name"])] += 1
        out.append((m["probe"], m["kind"], m["name"], j))
    return out


def _store():
    from thermotouch_models import DEFAULT_BUNDLE

    from edge.estimation.estimate import pipeline_golden_check
    from edge.model.bundle import load_bundle
    from firmware_sim.rigs.sequence_rig import OneBundleStore

    return OneBundleStore(load_bundle(DEFAULT_BUNDLE, golden_check=pipeline_golden_check))


def extend_head(head: str, objects, meta, extra: int, seed: int, rc_max: float, path, heat_s: float,
                board: str = "precision") -> None:
    """Touch every object ``extra`` more times on the drawn probes of ``meta``; saved after each object.

    The extension cache (``path``) holds touches only: the probes' references stay in the first
    pass's cache, so calibration is unchanged.  Saving after each object lets a run cut short still
    be read (``--reuse`` reads whatever objects it finished).
    """
    import tempfile

    store = _store()
    wd = tempfile.mkdtemp(prefix="tactile-asbuilt-ext-")
    n_probes = len({m["probe"] for m in meta})
    recs, new_meta, info = A.load_records(path) if path.exists() else ([], [], {})
    # A later pass draws from its own stream (the number of touches already added keys it).
    rng = np.random.default_rng([seed, len(head), EXTEND_SEED, len(new_meta)])
    meta = list(meta) + new_meta
    t0 = time.perf_counter() - (info.get("sim_s") or 0.0)
    for i, obj in enumerate(objects):
        j0 = 1 + max((m["j"] for m in meta if m.get("name") == obj.name and "j" in m), default=-1)
        for j in range(j0, j0 + extra):
            sp = A.specimen(obj, rng)
            hand = A.hand_draw(rng, rc_max)
            p = 1 + j % n_probes
            sc = A.hand_scene(head, sp, p, EXTEND_SEED + 1000 * i + j, heat_s=heat_s, label=obj.name,
                              board=board, **hand)
            recs.append(A.simulate(sc, store, wd, heat_s))
            new_meta.append({"kind": "touch", "probe": p, "name": obj.name, "j": j,
                             "e_true": sp.effusivity_W_s05_m2K, "alpha_true": sp.alpha_m2_s, **hand})
        A.save_records(path, recs, new_meta, {"sim_s": time.perf_counter() - t0, "argv": sys.argv[1:],
                                              "objects_done": i + 1})
        print(f"{head}: {obj.name} extended to {j0 + extra} ({time.perf_counter() - t0:.0f} s)", flush=True)


def probes_path(base, first: int, last: int, part: tuple[int, int] | None = None):
    """The cache file of new probes ``first..last`` (one part of ``n``, or the merged file)."""
    tail = "" if part is None or part[1] == 1 else f"_part{part[0]}of{part[1]}"
    return base.with_name(f"{base.stem}_probes{first}-{last}{tail}.npz")


def add_probes(head: str, objects, first: int, count: int, per_probe: int, part: tuple[int, int], seed: int,
               rc_max: float, base, heat_s: float, board: str = "precision") -> None:
    """Draw probes ``first .. first + count - 1`` (this part's share), calibrate-touch and touch each object.

    Probe ``p`` is drawn with seed ``p`` (:func:`firmware_sim.asbuilt.draw_as_built`, as the first
    pass's probes 1..3) and touched on :data:`_objects.REFERENCES` exactly as
    :func:`_asbuilt_touches.reference_records` does for the first pass; then every object
    ``per_probe`` times (fresh specimen and hand each, from a stream keyed by ``p``: the same touches
    whichever part runs the probe).  The part's file is saved after the references and after each
    object; a rerun of the same command resumes after the last saved object.
    """
    import tempfile

    i_part, n_part = part
    last = first + count - 1
    mine = [p for k, p in enumerate(range(first, last + 1)) if k % n_part == i_part - 1]
    path = probes_path(base, first, last, part)
    recs, meta, info = A.load_records(path) if path.exists() else ([], [], {})
    done = {(m["probe"], m["kind"], m["name"]) for m in meta}
    store = _store()
    wd = tempfile.mkdtemp(prefix="tactile-asbuilt-probes-")
    t0, c0 = time.perf_counter() - (info.get("sim_s") or 0.0), time.process_time() - (info.get("cpu_s") or 0.0)

    def save(note):
        A.save_records(path, recs, meta, {"sim_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0,
                                          "argv": sys.argv[1:], "probes": mine, "per_probe": per_probe})
        print(f"{head}: probe {note} ({time.perf_counter() - t0:.0f} s wall, {time.process_time() - c0:.0f} s CPU)",
              flush=True)

    for p in mine:
        if not any(d[0] == p and d[1] == "reference" for d in done):
            for name, r in A.reference_records(head, p, store, wd, board):
                recs.append(r)
                meta.append({"kind": "reference", "probe": p, "name": name})
            save(f"{p} references touched")
        rng = np.random.default_rng([seed, len(head), PROBES_SEED, p])
        for i, obj in enumerate(objects):
            # Draw even when resuming, so that a resumed probe's touches are the ones a full run makes.
            draws = [(A.specimen(obj, rng), A.hand_draw(rng, rc_max)) for _ in range(per_probe)]
            if (p, "touch", obj.name) in done:
                continue
            for k, (sp, hand) in enumerate(draws):
                sc = A.hand_scene(head, sp, p, PROBES_SEED + 10_000 * p + 100 * i + k, heat_s=heat_s,
                                  label=obj.name, board=board, **hand)
                recs.append(A.simulate(sc, store, wd, heat_s))
                meta.append({"kind": "touch", "probe": p, "name": obj.name, "j": PROBE_J * p + k,
                             "e_true": sp.effusivity_W_s05_m2K, "alpha_true": sp.alpha_m2_s, **hand})
            save(f"{p}: {obj.name} touched {per_probe}x")


_PROBES_RE = re.compile(r"_probes(\d+)-(\d+)(?:_part(\d+)of(\d+))?$")


def probe_files(base) -> list:
    """The ``--add-probes`` cache files of ``base`` (parts and merged files), sorted."""
    return sorted(p for p in base.parent.glob(f"{base.stem}_probes*.npz") if _PROBES_RE.search(p.stem))


def merge_probes(base) -> list:
    """Join each set of part files into its merged ``_probes<a>-<b>.npz`` (parts removed); the merged paths."""
    groups: dict = {}
    for p in probe_files(base):
        m = _PROBES_RE.search(p.stem)
        if m.group(3):
            groups.setdefault((int(m.group(1)), int(m.group(2))), []).append(p)
    out = []
    for (a, b), parts in groups.items():
        target = probes_path(base, a, b)
        recs, meta, info = A.load_records(target) if target.exists() else ([], [], {"parts": []})
        seen = set(record_keys(meta))
        for part in parts:
            r2, m2, i2 = A.load_records(part)
            for r, m, key in zip(r2, m2, record_keys(m2)):
                if key not in seen:
                    seen.add(key)
                    recs.append(r)
                    meta.append(m)
            # The parts ran side by side: the merged run's wall is the longest part's, its CPU their sum.
            info = {"sim_s": max(info.get("sim_s") or 0.0, i2.get("sim_s") or 0.0),
                    "cpu_s": (info.get("cpu_s") or 0.0) + (i2.get("cpu_s") or 0.0),
                    "parts": info.get("parts", []) + [{"file": part.name, **i2}]}
        A.save_records(target, recs, meta, info)
        for part in parts:
            part.unlink()
        out.append(target)
    return out


def complete_probes(meta, names) -> set:
    """The probes of ``meta`` with references and every object in ``names`` touched."""
    have: dict = {}
    for m in meta:
        have.setdefault(m["probe"], set()).add((m["kind"], m["name"] if m["kind"] == "touch" else ""))
    return {p for p, s in have.items() if ("reference", "") in s and all(("touch", n) in s for n in names)}


def load_all(path, names, *, extension: bool = True, probes: bool = True) -> tuple[list, list, dict]:
    """The first pass's records, its ``--extend`` touches and every complete ``--add-probes`` probe's.

    ``info`` sums the simulation's wall (``sim_s``) of the first pass and its extension, the added
    probes' CPU seconds (``probes_cpu_s``; merged parts: summed) and lists the probes left out
    because their run was cut short (``incomplete_probes``).
    """
    recs, meta, info = A.load_records(path)
    info = {**info, "files": [path.name]}
    ext = path.with_name(path.stem + "_ext.npz")
    more = ([ext] if extension and ext.exists() else []) + (probe_files(path) if probes else [])
    seen = set(record_keys(meta))
    dropped: set = set()
    for f in more:
        r2, m2, i2 = A.load_records(f)
        keep = complete_probes(m2, names) if "_probes" in f.stem else {m["probe"] for m in m2}
        dropped |= {m["probe"] for m in m2} - keep
        for r, m, key in zip(r2, m2, record_keys(m2)):
            if m["probe"] in keep and key not in seen:
                seen.add(key)
                recs.append(r)
                meta.append(m)
        if "_probes" in f.stem:   # run in parallel parts at low priority: their CPU seconds say what they cost
            info["probes_cpu_s"] = (info.get("probes_cpu_s") or 0.0) + (i2.get("cpu_s") or 0.0)
            info["probes_wall_s"] = max(info.get("probes_wall_s") or 0.0, i2.get("sim_s") or 0.0)
        else:
            info["sim_s"] = (info.get("sim_s") or 0.0) + (i2.get("sim_s") or 0.0)
        info["files"].append(f.name)
    # A probe cut short in one file may be complete in another (a later run drew the same probe again).
    info["incomplete_probes"] = sorted(dropped - {m["probe"] for m in meta})
    return recs, meta, info


def fill_references(head: str, base, board: str = "precision") -> list[tuple[str, int]]:
    """Touch again the references a merge dropped; (file, probe) of each probe filled.

    For every cache file of ``base`` (the first pass's and the ``--add-probes`` files) and every probe
    in it with fewer reference touches than :data:`_objects.REFERENCES`: the probe's references are
    simulated again (:func:`_asbuilt_touches.reference_records`: the same scenes and seeds), the
    touches the file kept must come out bit-identical -- the proof that the simulation is the one
    that made them -- and the probe's references are replaced by the full set, in order.  Saved per file.
    """
    import tempfile

    from _objects import REFERENCES

    store, wd, out = None, tempfile.mkdtemp(prefix="tactile-asbuilt-refs-"), []
    for path in [base] + probe_files(base):
        recs, meta, info = A.load_records(path)
        per_probe = Counter(m["probe"] for m in meta if m["kind"] == "reference")
        short = sorted(p for p, n in per_probe.items() if n < len(REFERENCES))
        if not short:
            continue
        for p in short:
            store = store or _store()
            fresh = A.reference_records(head, p, store, wd, board)
            kept = [(m["name"], r) for m, r in zip(meta, recs) if m["probe"] == p and m["kind"] == "reference"]
            for name, r in kept:
                if not any(n == name and _same(r, f) for n, f in fresh):
                    raise RuntimeError(f"{path.name}: probe {p}'s {name} touch is not what the simulation makes "
                                       "again: the cache was made by other code; not filled")
            first = next(i for i, m in enumerate(meta) if m["probe"] == p and m["kind"] == "reference")
            keep = [i for i, m in enumerate(meta) if not (m["probe"] == p and m["kind"] == "reference")]
            at = sum(1 for i in keep if i < first)
            recs = [recs[i] for i in keep]
            meta = [meta[i] for i in keep]
            recs[at:at] = [r for _, r in fresh]
            meta[at:at] = [{"kind": "reference", "probe": p, "name": n} for n, _ in fresh]
            out.append((path.name, p))
            print(f"{head}: {path.name}: probe {p}: {len(kept)} reference touches -> {len(fresh)}", flush=True)
        A.save_records(path, recs, meta, {**info, "references_filled": sorted(set(info.get("references_filled", []))
                                                                              | set(short))})
    return out


def _same(a, b) -> bool:
    """Two records bit-identical in their samples (None: no record)."""
    if a is None or b is None:
        return a is b
    return all(np.array_equal(getattr(a, n), getattr(b, n)) for n in ("t_s", "T_C", "q_W_m2"))
