"""Recorded touch series as CSV (or Parquet) files.

Schema: a header row, then one row per sample; columns (any order)

* ``t_s`` - time since heater-on (s), strictly increasing;
* ``T_C`` (the thermocouple as the device recorded it, °C), ``T_K`` (absolute
  temperature, K) or ``dT_K`` (excess over the baseline, K); with ``T_C`` or
  ``T_K`` the baseline is the mean of samples with t_s <= 0 if any, else the
  first sample;
* ``q_W_m2`` - heat flux into the object (W/m^2): the flux sensor's voltage over its
  nominal sensitivity;
* ``heater_W_m2`` (optional) - the heater's areal power;
* ``T_dt_s``, ``q_dt_s`` (optional) - each converter's read time against ``t_s``.

A device's touch record (``history --export-series``, :func:`write_touch`)
carries, before the column header, one ``# key: value`` line per field of
:data:`edge.estimation.record.HEADER_FIELDS` and the measurement's identity
(measurement id, started_utc, calibration and model sha256, software, board),
then the columns exactly as recorded (``t_s``, ``T_C``, ``q_W_m2`` and the read
times when recorded), every number written so that it reads back bit for bit;
:func:`read_touch` turns it back into the
:class:`~edge.estimation.record.TouchRecord` the device estimated.

Samples before heater-on (``t_s`` < 0) are kept by :func:`read_series`, for the
sensor-chain estimate, which fits from the moment of contact: a record that
starts with the probe in air lets it find that moment.

Lines starting with ``#`` are comments.  A comment of the form
``# key: value`` before the header row is metadata (:func:`read_record_metadata`);
``# probe: NAME`` names the probe head that took the record (a name in
:data:`edge.physics.geometry.PROBES`), which ``thermotouch estimate`` checks
against ``--probe``.  The file is UTF-8 text (a leading byte-order mark, as
some spreadsheets write, is accepted).  Errors name the line and column.

Parquet (``*.parquet``, with the optional ``pyarrow``: ``pip install
'thermotouch[parquet]'``) holds the same thing in a table: the same columns as
float64 (exact, no text round trip), each field's unit in its metadata
(:data:`COLUMN_UNITS`), and the ``# key: value`` header as the file's key-value
metadata (``kind`` says what the table is: ``touch`` or ``history``). Every
reader here takes either form by the file's suffix; a column whose unit is not
the one its name states, or a table of another kind, is refused by name.
"""

from __future__ import annotations

import csv
import math
import re
from pathlib import Path

import numpy as np


class RecordError(ValueError):
    """A malformed record file; the message names the line and column."""


#: Temperature columns a record may carry, the first found wins (the device's own first).
T_COLUMNS = ("T_C", "dT_K", "T_K")
#: Optional per-sample read times of the converters, s against ``t_s``.
READ_TIME_COLUMNS = ("T_dt_s", "q_dt_s")
_ZERO_C_K = 273.15
#: The unit of each record column (its name's suffix says it; a Parquet field carries it, and is checked).
COLUMN_UNITS = {"t_s": "s", "T_C": "degC", "T_K": "K", "dT_K": "K", "q_W_m2": "W/m^2", "heater_W_m2": "W/m^2",
                "T_dt_s": "s", "q_dt_s": "s"}
#: What a Parquet file from this module is, in its ``kind`` metadata.
PARQUET_KINDS = ("touch", "history")


# Keys may be dotted (``measurement.noise_T_K``: a device setting the touch was judged by).
_META = re.compile(r"^#\s*([A-Za-z_][A-Za-z0-9_.]*)\s*:\s*(.*?)\s*$")


def is_parquet(path: str | Path) -> bool:
    """Whether ``path`` names a Parquet file (by its suffix, as the writers choose the format)."""
    return Path(path).suffix.lower() == ".parquet"


def _parquet():
    try:
        import pyarrow  # noqa: PLC0415, F401
        import pyarrow.parquet as pq  # noqa: PLC0415
    except ImportError:
        raise RecordError("Parquet files need pyarrow (pip install 'thermotouch[parquet]')") from None
    return pq


def write_parquet(path: str | Path, columns: dict, meta: dict, units: dict[str, str], kind: str) -> None:
    """Write ``columns`` (name -> values) as one Parquet table, atomically.

    Parameters
    ----------
    columns : dict
        Column name -> 1-D values (NumPy arrays as float64, pyarrow arrays as they are, lists as
        pyarrow infers).
    meta : dict
        The file's key-value metadata (values written with :func:`_text`: one line each, None as 'none').
    units : dict
        Unit of each column that has one (field metadata ``unit``).
    kind : str
        What the table is (:data:`PARQUET_KINDS`), stored as ``kind``.
    """
    import pyarrow as pa  # noqa: PLC0415

    from host.atomic import atomic_path  # noqa: PLC0415

    pq = _parquet()
    if kind not in PARQUET_KINDS:
        raise ValueError(f"kind must be one of {PARQUET_KINDS}, got {kind!r}")
    fields, arrays = [], []
    for name, values in columns.items():
        if isinstance(values, pa.Array):
            arr = values
        elif isinstance(values, np.ndarray):
            arr = pa.array(np.asarray(values, dtype=np.float64))
        else:
            arr = pa.array(values)
        fields.append(pa.field(name, arr.type, metadata={"unit": units[name]} if name in units else None))
        arrays.append(arr)
    head = {"kind": kind, **{k: _text(v) for k, v in meta.items()}}
    table = pa.Table.from_arrays(arrays, schema=pa.schema(fields, metadata=head))
    with atomic_path(path) as tmp:
        pq.write_table(table, str(tmp))


def read_parquet(path: str | Path, kind: str) -> tuple[dict[str, np.ndarray | list], dict[str, str]]:
    """``(columns, metadata)`` of a Parquet table written by :func:`write_parquet` as ``kind``.

    Each column with a unit in its field metadata is checked against :data:`COLUMN_UNITS`.

    Raises
    ------
    RecordError
        Not readable as Parquet, another kind of table, or a column in another unit.
    """
    path = Path(path)
    pq = _parquet()
    import pyarrow as pa  # noqa: PLC0415

    try:
        table = pq.read_table(str(path))
    except OSError as exc:
        raise RecordError(f"{path}: cannot read ({getattr(exc, 'strerror', None) or exc})") from None
    except Exception as exc:  # noqa: BLE001 - pyarrow raises its own types for a file that is not Parquet
        raise RecordError(f"{path}: not a Parquet file ({type(exc).__name__}: {exc})") from None
    meta = {k.decode("utf-8", "replace"): v.decode("utf-8", "replace")
            for k, v in (table.schema.metadata or {}).items()}
    got = meta.pop("kind", None)
    if got != kind:
        raise RecordError(f"{path}: a Parquet table of kind {got!r}, not a {kind} "
                          f"({'history --export' if kind == 'history' else 'history --export-series'} writes those)")
    cols: dict[str, np.ndarray | list] = {}
    for field in table.schema:
        unit = (field.metadata or {}).get(b"unit")
        want = COLUMN_UNITS.get(field.name)
        if unit is not None and want is not None and unit.decode("utf-8", "replace") != want:
            raise RecordError(f"{path}, column '{field.name}': unit {unit.decode('utf-8', 'replace')!r}, "
                              f"but the name says {want}")
        col = table.column(field.name)
        cols[field.name] = (col.to_numpy().astype(np.float64) if pa.types.is_floating(field.type)
                            else col.to_pylist())
    return cols, meta


def read_record_metadata(path: str | Path) -> dict[str, str]:
    """``# key: value`` comments before the header row, as a dict (keys lower case; the first wins)."""
    path = Path(path)
    if is_parquet(path):
        return {k.lower(): v for k, v in read_parquet(path, "touch")[1].items()}
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
    if is_parquet(path):
        return _parquet_series(path)
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
    _check_columns(path, header_line, cols)
    if "t_s" not in cols or "q_W_m2" not in cols or not (set(T_COLUMNS) & set(cols)):
        raise RecordError(f"{path}, line {header_line}: header must have t_s, q_W_m2 and T_C, T_K or dT_K, "
                          f"got {cols}")
    tcol = next(c for c in T_COLUMNS if c in cols)
    want = {"t_s": cols.index("t_s"), tcol: cols.index(tcol), "q_W_m2": cols.index("q_W_m2")}
    for extra in ("heater_W_m2",) + READ_TIME_COLUMNS:
        if extra in cols:
            want[extra] = cols.index(extra)
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
    for extra in ("heater_W_m2",) + READ_TIME_COLUMNS:
        if extra in data:
            out[extra] = np.array(data[extra])
    return out


def _parquet_series(path: Path) -> dict[str, np.ndarray | str]:
    """:func:`read_series` of a Parquet touch record (the same checks; rows counted from 1)."""
    cols, _ = read_parquet(path, "touch")
    names = list(cols)
    _check_columns(path, 0, names)
    if "t_s" not in cols or "q_W_m2" not in cols or not (set(T_COLUMNS) & set(cols)):
        raise RecordError(f"{path}: columns must include t_s, q_W_m2 and T_C, T_K or dT_K, got {names}")
    tcol = next(c for c in T_COLUMNS if c in cols)
    out: dict[str, np.ndarray | str] = {"t_s": cols["t_s"], "T": cols[tcol], "q_W_m2": cols["q_W_m2"], "T_column": tcol}
    for extra in ("heater_W_m2",) + READ_TIME_COLUMNS:
        if extra in cols:
            out[extra] = cols[extra]
    for name, v in out.items():
        if isinstance(v, list):
            raise RecordError(f"{path}, column '{name}': not numbers")
        if isinstance(v, np.ndarray) and not np.all(np.isfinite(v)):
            raise RecordError(f"{path}, row {int(np.argmax(~np.isfinite(v))) + 1}, column '{name}': "
                              "value must be finite")
    t = out["t_s"]
    if t.size < 4:
        raise RecordError(f"{path}: need at least 4 samples, got {t.size}")
    bad = np.nonzero(np.diff(t) <= 0)[0]
    if bad.size:
        raise RecordError(f"{path}, row {int(bad[0]) + 2}, column 't_s': times must increase")
    return out


def _check_columns(path: Path, line: int, cols: list[str]) -> None:
    """Refuse a header whose columns are ambiguous: a name twice, or two temperature columns.

    Which one is meant cannot be guessed (the first used silently was wrong half of the time), so
    the user keeps one; no ``--accept`` overrides this.
    """
    seen: set[str] = set()
    for c in cols:
        if c and c in seen:
            raise RecordError(f"{path}, line {line}: column '{c}' appears twice (keep the one you mean)")
        seen.add(c)
    temps = [c for c in cols if c in T_COLUMNS]
    if len(temps) > 1:
        raise RecordError(f"{path}, line {line}: columns {' and '.join(temps)} together: the temperature is "
                          "ambiguous (keep one of them)")


#: Record checks ``--accept`` can waive (a record that is right although it looks wrong), and what each says.
CHECKS = {
    "time-units": "t_s looks like milliseconds",
    "temperature-units": "a temperature column's unit looks wrong",
    "flux-units": "q_W_m2 looks like the sensor's mV or V",
    "flux-sign": "the flux into the object is negative while heating",
    "constant-temperature": "the temperature does not change",
}
#: Longest plausible record without a stated sample rate (an older CSV), s: the device heats
#: < heater.max_on_time_s (10 s by default, 60 s at most in the protocol) after a baseline of seconds; t_s
#: spanning more, in steps of >= 1, is milliseconds. (An export states its rate, which is checked instead.)
MAX_RECORD_SPAN_s = 60.0
#: Below this an absolute temperature in K is not a room's or an object's (-73 degC): it is degC; above it, a
#: degC reading is not a touch (a contact probe's thermocouple tops out well below 200 degC): it is K.
T_UNIT_SPLIT = 200.0
#: Smallest mean flux into the object while heating, as a fraction of the heater's areal power. Simulated 2-s
#: touches of every library material at the paper's 1540 W/m^2 give 2.6 % (expanded polystyrene foam) to
#: 59 % (copper); the same flux written in mV of the 0.56 uV/(W/m^2) sensor is 0.056 % of it or less, in V
#: a thousand times less: 0.5 % is five times below the foam and ten times above copper in mV.
MIN_FLUX_FRACTION = 0.005
#: A sample rate stated in the header and the samples' mean rate may differ by this factor (the device's reads
#: jitter, and the thermocouple and flux converters interleave); t_s in ms is off by 1000.
RATE_FACTOR = 3.0


def check_record(record, t_column: str = "T_C", *, accept=(), source: str = "") -> None:
    """Refuse a record whose units or sign look wrong before it is estimated.

    Parameters
    ----------
    record : edge.estimation.record.TouchRecord
    t_column : str
        The temperature column the file had (``T_C``, ``T_K`` or ``dT_K``): which unit to expect.
    accept : iterable of str
        Names in :data:`CHECKS` the user says are intended (``--accept``).
    source : str
        The file, named in the message.

    Raises
    ------
    RecordError
        One line: what looks wrong, and the ``--accept`` that says it is intended.
    """
    from edge.physics.geometry import PROBES  # noqa: PLC0415

    accept = set(accept)
    where = f"{source}: " if source else ""

    def refuse(check: str, what: str) -> None:
        if check not in accept:
            raise RecordError(f"{where}{what} (if it is intended, give --accept {check})")

    t, q = record.t_s, record.q_W_m2
    exported = "measurement_id" in record.meta or record.meta.get("header") != "none (older CSV)"
    steps = np.diff(t)
    step = float(np.median(steps)) if steps.size else 0.0
    span = float(t[-1] - t[0])
    # An export states its sample rate (checked next); an armed export at 1 Hz may span 120 s of arming.
    if not exported and span > MAX_RECORD_SPAN_s and step >= 1.0:
        refuse("time-units", f"t_s spans {span:g} s in steps of {step:g} s: it looks like milliseconds "
                             "(divide by 1000)")
    rate = record.sample_rate_Hz
    shown = (t.size - 1) / span if span > 0 else rate  # the samples' mean rate (the device's reads jitter)
    if not 1.0 / RATE_FACTOR <= shown / rate <= RATE_FACTOR:
        refuse("time-units", f"the header's sample_rate_Hz {rate:g} disagrees with the samples' "
                             f"{shown:.3g} Hz (t_s in other units?)")
    if t_column != "dT_K":
        T_abs = np.median(record.T_C) + (_ZERO_C_K if t_column == "T_K" else 0.0)
        if t_column == "T_K" and T_abs < T_UNIT_SPLIT:
            refuse("temperature-units", f"column T_K reads {T_abs:.4g}: it looks like degC (name the column T_C)")
        if t_column == "T_C" and T_abs > T_UNIT_SPLIT:
            refuse("temperature-units", f"column T_C reads {T_abs:.4g}: it looks like kelvin (name the column T_K)")
    heating = (t > 0) & (t <= record.heater_on_s)
    if np.count_nonzero(heating) < 2:
        return
    if np.ptp(record.T_C[heating]) == 0.0:
        refuse("constant-temperature", f"the temperature is {record.T_C[heating][0]:g} throughout the heating: nothing was measured "
                                       "(the thermocouple column?)")
    if exported:
        # A device's export: the device converted its own sensor to W/m^2, and a weak or odd flux is its
        # measurement (a touch in air, flagged no_contact), which estimate must reproduce, not refuse.
        return
    before = t < 0
    q_heat = float(np.mean(q[heating]) - (np.mean(q[before]) if before.any() else 0.0))
    geometry = PROBES.get(record.probe)
    if geometry is None:
        return
    expected = record.power_W / geometry.heater_area_m2  # the heater's areal power, W/m^2
    if q_heat < 0 and abs(q_heat) >= MIN_FLUX_FRACTION * expected:
        refuse("flux-sign", f"the mean flux while heating is {q_heat:.4g} W/m^2, negative: the sensor's sign "
                            "looks inverted (q_W_m2 is the flux into the object)")
    elif abs(q_heat) < MIN_FLUX_FRACTION * expected:
        refuse("flux-units", f"the mean flux while heating is {q_heat:.3g} W/m^2, under "
                             f"{MIN_FLUX_FRACTION:.1%} of the heater's {expected:.4g} W/m^2: it looks like the "
                             "sensor's mV or V, not W/m^2")


def read_record(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t_s, dT_K, q_W_m2) from a CSV file, samples with t_s >= 0 only."""
    s = read_series(path)
    t, T, q = s["t_s"], s["T"], s["q_W_m2"]
    if s["T_column"] != "dT_K":
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


def _text(value) -> str:
    """A header value as one line that reads back as the same value."""
    if value is None:
        return "none"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float, np.integer, np.floating)):
        return repr(float(value)) if not isinstance(value, (int, np.integer)) else str(int(value))
    return " ".join(str(value).split())  # one line: a newline would end the header entry


def _number(v) -> str:
    # repr is the shortest text that parses back to the same float64: the export is bit-exact.
    return repr(float(v))


def write_touch(path: str | Path, record, identity=None) -> None:
    """Write a device's touch record with its header, atomically (the schema in the module docstring).

    Parameters
    ----------
    path : path-like
    record : edge.estimation.record.TouchRecord
    identity : mapping, optional
        The measurement's identity written first (measurement_id, started_utc, calibration_sha256,
        model_sha256, software, board ...); None values are left out. The record's own header
        fields win over a key of the same name.
    """
    from host.atomic import atomic_path  # noqa: PLC0415

    head = {k: v for k, v in dict(identity or {}).items() if v is not None}
    head.update(record.header())
    names = ["t_s", "T_C", "q_W_m2"]
    columns = [record.t_s, record.T_C, record.q_W_m2]
    for name in READ_TIME_COLUMNS:
        if getattr(record, name) is not None:
            names.append(name)
            columns.append(getattr(record, name))
    for key in head:
        if _META.match(f"# {key}: x") is None:
            raise ValueError(f"header key {key!r} is not a name")
    if is_parquet(path):
        write_parquet(path, {n: np.asarray(c, dtype=np.float64) for n, c in zip(names, columns)}, head,
                      COLUMN_UNITS, "touch")
        return
    with atomic_path(path) as tmp, open(tmp, "w", newline="", encoding="utf-8") as f:
        f.write("# ThermoTouch touch record: the device's raw samples (t_s from heater-on, negative before; "
                "T_C thermocouple; q_W_m2 flux sensor) and what it knew\n")
        for key, value in head.items():
            if _META.match(f"# {key}: x") is None:
                raise ValueError(f"header key {key!r} is not a name")
            f.write(f"# {key}: {_text(value)}\n")
        w = csv.writer(f)
        w.writerow(names)
        for row in zip(*columns):
            w.writerow([_number(v) for v in row])


def _header(path: Path) -> dict[str, str]:
    """``# key: value`` lines before the column header, keys as written (the first wins)."""
    if is_parquet(path):
        return read_parquet(path, "touch")[1]
    meta: dict[str, str] = {}
    for line in Path(path).read_bytes().decode("utf-8-sig").splitlines():
        s = line.strip()
        if not s:
            continue
        if not s.startswith("#"):
            break
        m = _META.match(s)
        if m:
            meta.setdefault(m.group(1), m.group(2))
    return meta


def read_touch(path: str | Path, probe: str | None = None, *, accept=()):
    """A record file as the :class:`~edge.estimation.record.TouchRecord` to estimate.

    A device's export (its header names the touch: probe, power, heater on-time, sample clock,
    baseline ...) reads back as the record the device estimated. An older CSV without that
    header (``t_s``, ``T_K`` or ``dT_K``, ``q_W_m2``; ``# probe:`` optional) is read as before:
    ``probe`` (``--probe``) names the head when the file does not, the heater is taken as on from
    t_s = 0 to the last sample, the baseline is what comes before 0, the clock is the median
    sample interval and the power is ``heater_W_m2`` times the heater's area, or the head's
    nominal power when the file has no such column.

    The record is then checked (:func:`check_record`): units and sign that look wrong are refused
    unless ``accept`` names the check.

    Raises
    ------
    RecordError
        One line naming the file and what is wrong.
    """
    from edge.estimation.record import HEADER_FIELDS, TouchRecord  # noqa: PLC0415
    from edge.estimation.record import RecordError as BadRecord  # noqa: PLC0415
    from edge.physics.geometry import PROBES  # noqa: PLC0415

    path = Path(path)
    s = read_series(path)  # the file's own checks first: they name the line and column
    meta = _header(path)
    t, T, q = s["t_s"], s["T"], s["q_W_m2"]
    T_C = T - _ZERO_C_K if s["T_column"] == "T_K" else T
    # Header keys match the record's fields whatever their case (a spreadsheet may have changed it).
    canonical = {f.lower(): f for f in HEADER_FIELDS}
    header = {canonical.get(k.lower(), k): v for k, v in meta.items()}
    recorded = header.get("probe")
    exported = any(f in header for f in HEADER_FIELDS if f != "probe")
    # An export names its probe; an older CSV is the paper probe's unless --probe or its probe line says.
    name = (probe or recorded) if exported else (probe or "paper")
    if name is None:
        raise RecordError(f"{path}: header lacks probe (or give --probe)")
    if recorded is not None and recorded != name:
        raise RecordError(f"{path} was taken with probe {recorded!r}, not --probe {name}")
    if name not in PROBES:
        raise RecordError(f"{path}: unknown probe {name!r}; shipped: {', '.join(PROBES)}")
    try:
        if exported:
            # A device's export: every field as the device had it.
            record = TouchRecord.from_header(header, t, T_C, q, s.get("T_dt_s"), s.get("q_dt_s"))
        else:
            record = _older_record(path, name, s, T_C, {k: v for k, v in header.items() if k != "probe"})
    except BadRecord as exc:
        raise RecordError(f"{path}: {exc}") from None
    check_record(record, s["T_column"], accept=accept, source=str(path))
    return record


def _older_record(path: Path, name: str, s: dict, T_C: np.ndarray, meta: dict):
    """A record without a device's header, as ``estimate`` always read one (see :func:`read_touch`).

    Its baseline is what the file says it is: the samples before heater-on, or -- when it starts at
    heater-on -- the excess's zero (``dT_K``) or the first reading (``T_K``, ``T_C``), with no flux
    offset; one sample before heater-on carries that baseline, so the record goes through the one
    estimate path like any other.
    """
    from edge.estimation.record import TouchRecord  # noqa: PLC0415
    from edge.physics.geometry import PROBES  # noqa: PLC0415

    geometry = PROBES[name]
    t, q = s["t_s"], s["q_W_m2"]
    dt = float(np.median(np.diff(t)))
    dts = [s.get(c) for c in READ_TIME_COLUMNS]
    if t[0] >= 0:
        T_base = 0.0 if s["T_column"] == "dT_K" else float(T_C[0])
        t, T_C, q = (np.concatenate(([min(t[0] - dt, -dt)], t)), np.concatenate(([T_base], T_C)),
                     np.concatenate(([0.0], q)))
        dts = [None if a is None else np.concatenate(([0.0], a)) for a in dts]
    heating = s["t_s"] > 0
    power_W = geometry.nominal_power_W
    if "heater_W_m2" in s and heating.any():
        power_W = float(np.mean(s["heater_W_m2"][heating])) * geometry.heater_area_m2
    return TouchRecord(probe=name, t_s=t, T_C=T_C, q_W_m2=q, power_W=power_W, heater_on_s=max(float(t[-1]), 0.0),
                       sample_rate_Hz=1.0 / dt, baseline_s=-float(t[0]), T_dt_s=dts[0], q_dt_s=dts[1],
                       meta=meta | {"header": "none (older CSV)"})
