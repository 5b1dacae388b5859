"""Hand touches of specimens on drawn as-built probes, their calibration, and a cache of the raw records.

Shared by bench/tactile_asbuilt_bench.py (recognition at 0.5 / 1 / 2 s on both heads).  Every
touch runs through the device's own code on the emulated chips
(:func:`asbuilt_bench.scene_for`, :func:`firmware_sim.rigs.sequence_rig.sequence_touch`): the
sequence, the drivers, the converters; the world is the faithful axisymmetric model of a probe drawn
by :func:`firmware_sim.asbuilt.draw_as_built` (the device is told only the nominal probe).  What is
kept is the device's raw :class:`~edge.estimation.record.TouchRecord`, so every estimate (any
calibration, any contact time up to the heating simulated) is made afterwards from the cache by
:func:`edge.estimation.seam.estimate_touch` -- re-estimation never re-simulates.

A record of ``heat_s`` of heating holds every shorter touch: heating is causal, so the first
``t`` seconds of a 2-s touch are a ``t``-second touch (:func:`truncated`).

Calibration: each drawn probe is calibrated as ``thermotouch calibrate`` does (host/cli/calibrate.py:
the head's fit, the leave-one-reference-out self-check and the re-measure through the estimate path,
:func:`host.calibration.checked_calibration`), on reference touches of that probe: the paper probe's
:data:`_objects.REFERENCES` (hand touches, recorded from before contact, 8 s of heating), the small
head's ideal-contact 5-s touches of the same three references.  A calibration the self-check refuses
is kept (``force``: flagged, with its model-form floor), and the refusal reported.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from pathlib import Path

import numpy as np

from _common import RESULTS
from asbuilt_bench import scene_for
from edge.estimation.record import HEADER_FIELDS, TouchRecord
from edge.physics.solids import Solid
from firmware_sim.scene.model import ObjectSpec

CACHE = RESULTS / "cache"
#: Reference touches of the small head: ideal contact from heater-on (what its flux-scale fit expects).
SMALL_REF_HEAT_s = 5.0
#: The base scene's object thickness is replaced by a thick block (every everyday object as semi-infinite
#: over 2 s of heating: a 1 cm polymer or a 3 cm metal would be; the objects are not plates here).
OBJECT_THICKNESS_m = 0.1


#: The reference board (MCP9600 thermocouple converter + ADS1115 flux ADC) as a shipped paper scene reads it.
REFERENCE_BOARD_SCENE = "glass_15V_faithful"


def hand_scene(head: str, solid: Solid, draw_seed: int | None, seed: int, *, rc_m2K_W: float, offset_K: float,
               lead_s: float, heat_s: float, label: str = "specimen", board: str = "precision"):
    """The head's base scene touching ``solid`` by hand: R_c, object - probe, contact ``lead_s`` before heating.

    ``board``: ``"precision"`` (the base scene's ADS122C04) or ``"reference"`` (paper head only:
    :data:`REFERENCE_BOARD_SCENE`'s chips and noise).
    """
    sc = scene_for(head, "pmma", draw_seed, seed)
    if board == "reference":
        if head != "paper":
            raise ValueError("the reference board is modelled for the paper head only")
        from firmware_sim.scene.files import read_scene  # noqa: PLC0415

        ref = read_scene(REFERENCE_BOARD_SCENE)
        sc = dataclasses.replace(sc, board=ref.board, sensors=ref.sensors)
    touch = dataclasses.replace(sc.touch, start_s=0.5, length_s=lead_s + heat_s + 0.8, contact_lead_s=lead_s,
                                contact_resistance_m2K_W=rc_m2K_W, object_offset_K=offset_K,
                                object_temperature_C=None)
    obj = ObjectSpec(solid=solid, back="insulated", thickness_m=OBJECT_THICKNESS_m, label=label)
    return dataclasses.replace(sc, touch=touch, object=obj, contact_resistance_m2K_W=rc_m2K_W)


def simulate(scene, store, workdir: str, heat_s: float) -> TouchRecord | None:
    """The device's raw record of one touch (None when the sequence kept none)."""
    from firmware_sim.rigs.sequence_rig import sequence_touch  # noqa: PLC0415

    out, _, _ = sequence_touch(scene, store, workdir, {"measurement": {"contact_time_s": heat_s}})
    return out.touch


def truncated(rec: TouchRecord, heat_s: float) -> TouchRecord:
    """The record of the same touch heated only ``heat_s`` (its first ``heat_s`` of heating)."""
    if heat_s >= rec.heater_on_s - 1e-9:
        return rec
    keep = rec.t_s <= heat_s + 0.5 / rec.sample_rate_Hz
    cut = {n: (None if getattr(rec, n) is None else getattr(rec, n)[keep]) for n in ("T_dt_s", "q_dt_s")}
    return dataclasses.replace(rec, t_s=rec.t_s[keep], T_C=rec.T_C[keep], q_W_m2=rec.q_W_m2[keep],
                               heater_on_s=float(heat_s), **cut)


# -- cache -----------------------------------------------------------------------------------------
def _header(rec: TouchRecord) -> dict:
    return {k: getattr(rec, k) for k in HEADER_FIELDS}


def save_records(path: Path, records: list[TouchRecord | None], meta: list[dict], info: dict) -> None:
    """Records (None: no record), one meta dict each and the run's info, in one compressed npz."""
    arrays: dict[str, np.ndarray] = {}
    heads = []
    for i, r in enumerate(records):
        if r is None:
            heads.append(None)
            continue
        heads.append(_header(r))
        arrays[f"t{i}"], arrays[f"T{i}"], arrays[f"q{i}"] = r.t_s, r.T_C, r.q_W_m2
        for n in ("T_dt_s", "q_dt_s"):
            if getattr(r, n) is not None:
                arrays[f"{n}{i}"] = getattr(r, n)
    arrays["json"] = np.array(json.dumps({"headers": heads, "meta": meta, "info": info}))
    path.parent.mkdir(parents=True, exist_ok=True)
    # Written beside and renamed into place: a run killed while saving leaves the last complete file.
    tmp = path.with_name(path.stem + ".tmp.npz")
    np.savez_compressed(tmp, **arrays)
    os.replace(tmp, path)


def load_records(path: Path) -> tuple[list[TouchRecord | None], list[dict], dict]:
    """What :func:`save_records` wrote."""
    with np.load(path) as z:
        d = json.loads(str(z["json"]))
        recs: list[TouchRecord | None] = []
        for i, h in enumerate(d["headers"]):
            if h is None:
                recs.append(None)
                continue
            extra = {n: z[f"{n}{i}"] for n in ("T_dt_s", "q_dt_s") if f"{n}{i}" in z}
            recs.append(TouchRecord(t_s=z[f"t{i}"], T_C=z[f"T{i}"], q_W_m2=z[f"q{i}"], **h, **extra))
    return recs, d["meta"], d["info"]


# -- calibration of a drawn probe -------------------------------------------------------------------
def reference_records(head: str, draw_seed: int, store, workdir: str, board: str = "precision"
                      ) -> list[tuple[str, TouchRecord | None]]:
    """The reference touches of one drawn probe, as ``thermotouch calibrate``'s walk-through takes them."""
    from _objects import REFERENCES  # noqa: PLC0415
    from asbuilt_bench import solid  # noqa: PLC0415
    from host.calibration import HEAT_s  # noqa: PLC0415

    out = []
    for j, (name, rc, off) in enumerate(REFERENCES):
        if head == "paper":
            sc = hand_scene(head, solid(name), draw_seed, 7000 + 13 * draw_seed + j, rc_m2K_W=rc, offset_K=off,
                            lead_s=1.0, heat_s=HEAT_s, label=name, board=board)
            out.append((name, simulate(sc, store, workdir, HEAT_s)))
        else:
            sc = hand_scene(head, solid(name), draw_seed, 7000 + 13 * draw_seed + j, rc_m2K_W=0.0, offset_K=0.0,
                            lead_s=0.0, heat_s=SMALL_REF_HEAT_s, label=name)
            out.append((name, simulate(sc, store, workdir, SMALL_REF_HEAT_s)))
    return out


def calibrate_records(head: str, refs: list[tuple[str, TouchRecord | None]]):
    """(ProbeCalibration, self-check dict) from reference records, through the code ``thermotouch calibrate`` runs."""
    from edge.calibration.fit import OTHER_REFERENCE_U_REL, REFERENCE_U_REL  # noqa: PLC0415
    from edge.physics.materials import load_materials  # noqa: PLC0415
    from host.calibration import checked_calibration, seam_remeasure  # noqa: PLC0415
    from host.cli.common import seam_context  # noqa: PLC0415

    lib = load_materials()
    refs = [(n, r) for n, r in refs if r is not None]
    names = [n for n, _ in refs]
    mats = [lib.get(n) for n in names]
    e_refs = [m.solid.effusivity_W_s05_m2K for m in mats]
    u_refs = [REFERENCE_U_REL.get(n, OTHER_REFERENCE_U_REL) for n in names]
    records = [r for _, r in refs]
    ctx = {}
    contexts = [ctx.setdefault(r.method, seam_context(None, method=r.method)) for r in records]
    if head == "paper":
        from edge.calibration.fit import ReferenceTouch, fit_calibration  # noqa: PLC0415
        from host.records import uniform_series  # noqa: PLC0415

        touches = [ReferenceTouch(n, e, *uniform_series(r.t_s, r.T_C, r.q_W_m2)) for n, e, r in
                   zip(names, e_refs, records)]
        fit = lambda tt, k: fit_calibration(tt, probe=head, min_references=k)  # noqa: E731
    else:
        from edge.calibration.axi import AxiReferenceTouch, fit_flux_scale  # noqa: PLC0415
        from edge.estimation.probe_estimate import AxiEstimator  # noqa: PLC0415
        from host.cli.common import load_estimator  # noqa: PLC0415

        touches = []
        for n, m, u, r in zip(names, mats, u_refs, records):
            pre, keep = r.t_s <= 0, r.t_s >= 0
            dT = r.T_C - (r.T_C[pre].mean() if pre.any() else r.T_C[0])
            touches.append(AxiReferenceTouch(n, m.solid.k_W_mK, m.solid.alpha_m2_s, u, r.t_s[keep], dT[keep],
                                             r.q_W_m2[keep]))
        est, _ = load_estimator(None)
        axi = AxiEstimator(est, head)
        fit = lambda tt, k: fit_flux_scale(axi, tt, min_references=k)  # noqa: E731
    cal, check = checked_calibration(fit, touches, names, e_refs, u_refs, seam_remeasure(records, contexts),
                                     force=True)
    return cal, check.to_dict()


def scene_noise(head: str, board: str = "precision") -> tuple[float, float, float]:
    """(sigma_T_K, sigma_q_W_m2, dt_s) the simulated touches of :func:`hand_scene` carry: one sample's noise.

    What the attainable u of the bench's Bayes rate is computed with (:func:`sensor_noise` of the
    head's hand scene on ``board``).
    """
    sc = hand_scene(head, Solid(k_W_mK=0.2, rho_kg_m3=1190.0, c_J_kgK=1470.0), None, 0, rc_m2K_W=0.0,
                    offset_K=0.0, lead_s=0.0, heat_s=1.0, board=board)
    return sensor_noise(sc, board)


def sensor_noise(sc, board: str = "precision") -> tuple[float, float, float]:
    """(sigma_T_K, sigma_q_W_m2, dt_s) of one sample of scene ``sc`` on ``board``.

    The scene's ``[sensors]`` input noise of the chip playing each role on ``board``
    (:data:`edge.hw.chips.BOARDS`), in K and W/m^2 at the nominal sensitivities, and each
    converter's step as uniform rounding (step / sqrt 12), in quadrature; the interval of the
    board's samples (:func:`host.objects.board_noise`).  Not the registry's instrument model, whose
    flux noise adds a cable's pick-up the scenes do not simulate.
    """
    from edge.hw.chips import BOARDS, CHIPS, FLUX, THERMOCOUPLE, TYPE_K_SEEBECK_V_per_K  # noqa: PLC0415
    from host.objects import board_noise  # noqa: PLC0415

    if any(sc.board.address_of(c) is None for c in BOARDS[board].values()):
        raise ValueError(f"scene {sc.name} does not fit the {board} board's chips {dict(BOARDS[board])}")
    out = []
    for role, per_V in ((THERMOCOUPLE, TYPE_K_SEEBECK_V_per_K), (FLUX, sc.sensors.flux_sensitivity_V_per_W_m2)):
        spec = CHIPS[BOARDS[board][role]]
        noise_V = getattr(sc.sensors, spec.setting_key(spec.input_noise.key))
        out.append(spec.models[role].reading_sd(noise_V / per_V))
    return out[0], out[1], board_noise(board)[2]


def hand_draw(rng: np.random.Generator, rc_max_m2K_W: float) -> dict:
    """One hand touch: R_c uniform in [0, rc_max], object - probe uniform in +-2 K, contact 0.5-3 s before heating."""
    return {"rc_m2K_W": float(rng.uniform(0.0, rc_max_m2K_W)), "offset_K": float(rng.uniform(-2.0, 2.0)),
            "lead_s": float(rng.uniform(0.5, 3.0))}


def specimen(obj, rng: np.random.Generator) -> Solid:
    """One specimen of a KnownObject: ln e and ln α drawn independently with its spread (host.recognition's)."""
    e = obj.e_W_s05_m2K * math.exp(rng.normal(0.0, obj.spread_rel))
    alpha = obj.alpha_m2_s * math.exp(rng.normal(0.0, obj.spread_rel))
    rho_c = e / math.sqrt(alpha)
    return Solid(k_W_mK=e * math.sqrt(alpha), rho_kg_m3=rho_c / 1000.0, c_J_kgK=1000.0)
