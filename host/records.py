"""Recorded touch series as CSV files.

Schema: a header row, then one row per sample; columns (any order)

* ``t_s`` - time since heater-on (s), strictly increasing;
* ``T_K`` (absolute temperature, K) or ``dT_K`` (excess over the baseline, K);
  with ``T_K`` the baseline is the mean of samples with t_s <= 0 if any, else
  the first sample;
* ``q_W_m2`` - heat flux into the object (W/m^2): the flux sensor's voltage over its
  nominal sensitivity;
* ``heater_W_m2`` (optional) - the heater's areal power.

Samples before heater-on (``t_s`` < 0) are kept by :func:`read_series`, for the
sensor-chain estimate, which fits from the moment of contact: a record that
starts with the probe in air lets it find that moment.

Lines starting with ``#`` are comments.  A comment of the form
``# key: value`` before the header row is metadata (:func:`read_record_metadata`);
``# probe: NAME`` names the probe head that took the record (a name in
:data:`edge.physics.geometry.PROBES`), which ``thermotouch estimate`` checks
against ``--probe``.  The file is UTF-8 text (a leading byte-order mark, as
some spreadsheets write, is accepted).  Errors name the line and column.
"""

from __future__ import annotations

import csv
import math
import re
from pathlib import Path

import numpy as np


class RecordError(ValueError):
    """A malformed record file; the message names the line and column."""


_META = re.compile(r"^#\s*([A-Za-z_][A-Za-z0-9_]*)\s*:\s*(.*?)\s*$")


def read_record_metadata(path: str | Path) -> dict[str, str]:
    """``# key: value`` comments before the header row, as a dict (keys lower case; the first wins)."""
    path = Path(path)
    try:
        text = path.read_bytes().decode("utf-8-sig")
    except OSError as exc:
        raise RecordError(f"{path}: cannot read ({exc.strerror})") from None
    except UnicodeDecodeError as exc:
        raise RecordError(f"{path}: not a text CSV file (byte {exc.start} is not UTF-8)") from None
    meta: dict[str, str] = {}
    for line in text.splitlines():
        s = line.strip()
        if not s:
            continue
        if not s.startswith("#"):
            break  # the header row: metadata ends there
        m = _META.match(s)
        if m:
            meta.setdefault(m.group(1).lower(), m.group(2))
    return meta


def read_series(path: str | Path) -> dict[str, np.ndarray | str]:
    """The whole record, samples before heater-on included (for the sensor chain and calibration).

    Returns ``t_s``, ``T`` (the ``T_K`` or ``dT_K`` column as written), ``q_W_m2``, ``heater_W_m2``
    (absent: not in the file) and ``T_column`` (which one was found).
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise RecordError(f"{path}: cannot read ({exc.strerror})") from None
    try:
        text = data.decode("utf-8-sig")  # a spreadsheet's byte-order mark is not part of the header
    except UnicodeDecodeError as exc:
        raise RecordError(f"{path}: not a text CSV file (byte {exc.start} is not UTF-8)") from None
    if "\x00" in text:
        raise RecordError(f"{path}: not a text CSV file (contains NUL bytes)")
    rows = [(i + 1, line) for i, line in enumerate(text.splitlines()) if line.strip() and not line.lstrip().startswith("#")]
    if not rows:
        raise RecordError(f"{path}: empty file")
    header_line, header = rows[0]
    cols = [c.strip() for c in next(csv.reader([header]))]
    if "t_s" not in cols or "q_W_m2" not in cols or not ({"T_K", "dT_K"} & set(cols)):
        raise RecordError(f"{path}, line {header_line}: header must have t_s, q_W_m2 and T_K or dT_K, got {cols}")
    tcol = "dT_K" if "dT_K" in cols else "T_K"
    want = {"t_s": cols.index("t_s"), tcol: cols.index(tcol), "q_W_m2": cols.index("q_W_m2")}
    if "heater_W_m2" in cols:
        want["heater_W_m2"] = cols.index("heater_W_m2")
    data = {k: [] for k in want}
    for line_no, line in rows[1:]:
        fields = next(csv.reader([line]))
        if len(fields) != len(cols):
            raise RecordError(f"{path}, line {line_no}: expected {len(cols)} fields, got {len(fields)}")
        for name, j in want.items():
            try:
                v = float(fields[j])
            except ValueError:
                raise RecordError(f"{path}, line {line_no}, column '{name}': {fields[j].strip()!r} is not a number") from None
            if not math.isfinite(v):
                raise RecordError(f"{path}, line {line_no}, column '{name}': value must be finite")
            data[name].append(v)
    t = np.array(data["t_s"])
    if t.size < 4:
        raise RecordError(f"{path}: need at least 4 samples, got {t.size}")
    bad = np.nonzero(np.diff(t) <= 0)[0]
    if bad.size:
        raise RecordError(f"{path}, line {rows[1 + bad[0] + 1][0]}, column 't_s': times must increase")
    out: dict[str, np.ndarray | str] = {"t_s": t, "T": np.array(data[tcol]), "q_W_m2": np.array(data["q_W_m2"]),
                                        "T_column": tcol}
    if "heater_W_m2" in data:
        out["heater_W_m2"] = np.array(data["heater_W_m2"])
    return out


def read_record(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t_s, dT_K, q_W_m2) from a CSV file, samples with t_s >= 0 only."""
    s = read_series(path)
    t, T, q = s["t_s"], s["T"], s["q_W_m2"]
    if s["T_column"] == "T_K":
        pre = t <= 0
        T = T - (T[pre].mean() if pre.any() else T[0])
    keep = t >= 0
    if np.count_nonzero(keep) < 4:
        raise RecordError(f"{path}: need at least 4 samples at t_s >= 0, got {np.count_nonzero(keep)}")
    return t[keep], T[keep], q[keep]


def uniform_series(t_s: np.ndarray, *columns: np.ndarray, path: str | Path = "") -> tuple[np.ndarray, ...]:
    """The columns on a uniform grid (:func:`edge.estimation.chain_estimate.uniform_record`), errors named by file."""
    from edge.estimation.chain_estimate import uniform_record  # noqa: PLC0415

    try:
        return uniform_record(t_s, *columns)
    except ValueError as exc:
        raise RecordError(f"{path}: {exc}") from None


def _write_csv(path: str | Path, header: str, columns: tuple[str, str, str], rows, probe: str | None) -> None:
    from host.atomic import atomic_path  # noqa: PLC0415

    with atomic_path(path) as tmp, open(tmp, "w", newline="", encoding="utf-8") as f:
        f.write(f"# {header}\n")
        if probe is not None:
            f.write(f"# probe: {probe}\n")
        w = csv.writer(f)
        w.writerow(list(columns))
        for row in rows:
            w.writerow([f"{v:.9g}" for v in row])


def write_record(path: str | Path, t_s, dT_K, q_W_m2, *, probe: str | None = None) -> None:
    """Write a record in the schema above (dT_K column), atomically; ``probe``: its ``# probe:`` line."""
    _write_csv(path, "ThermoTouch record: time since heater-on, excess temperature, flux into the object",
               ("t_s", "dT_K", "q_W_m2"), zip(t_s, dT_K, q_W_m2), probe)


def write_series(path: str | Path, t_s, T_K, q_W_m2, *, probe: str | None = None) -> None:
    """Write a whole record (absolute ``T_K``, samples before heater-on included), atomically."""
    _write_csv(path, "ThermoTouch record: time since heater-on (negative before), thermocouple, flux-sensor reading",
               ("t_s", "T_K", "q_W_m2"), zip(t_s, T_K, q_W_m2), probe)
