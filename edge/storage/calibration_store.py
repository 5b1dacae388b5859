"""The probe's calibration on the device: one verified file, replaced atomically.

A calibration (:class:`edge.calibration.model.ProbeCalibration`) is a few kB of
JSON; the device keeps the one in use as ``calibration.json`` in its store
directory, with the signature it was installed with beside it
(``calibration.sig``).  Installing checks, in order: size, UTF-8 JSON and
every field (with the file's own SHA-256), the probe it was made for against
the device's, and the update policy's signature rule over the exact bytes
(as model bundles and object sets).  Then the bytes are written with
:func:`edge.storage.durable.atomic_write_file` (a crash leaves the old
calibration or the new one), the signature first: a calibration is never
on disk without the signature that let it in (a crash between the two
leaves the old calibration beside the new signature: ``signed_by`` is then
wrong until the next install, the calibration in use is still whole).
Reading back re-checks the fields and the checksum (a damaged file is
named, never used).

The store knows files, not what a calibration means: the caller gives it the
parser (``ProbeCalibration.from_json`` on the device, :mod:`edge.service.calibration`)
and the size bound, so storage does not import the calibration model above it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Protocol

from edge.security.policy import UpdateRefused
from edge.storage import durable

__all__ = ["CalibrationStore", "CalibrationStoreError", "StoredCalibration"]

FILE = "calibration.json"
SIGNATURE = "calibration.sig"


class CalibrationStoreError(ValueError):
    """A calibration refused on install, or a stored one that cannot be read; the message says why."""


class StoredCalibration(Protocol):
    """What the store reads of a parsed calibration (:class:`edge.calibration.model.ProbeCalibration` has it)."""

    #: The probe head it was made for.
    probe: str
    #: False for the uncalibrated datasheet chain (never installed).
    calibrated: bool


class CalibrationStore:
    """The device's calibration store.

    Parameters
    ----------
    root : path-like
        Store directory (created if missing).
    probe : str
        The device's probe head; a calibration made for another is refused.
    policy : edge.security.policy.UpdatePolicy, optional
        Who may install (None: nobody).
    parse : callable (bytes) -> StoredCalibration
        Parses and checks a calibration file's bytes, raising ``ValueError`` naming the problem
        (``edge.calibration.model.ProbeCalibration.from_json``).
    max_bytes : int
        Largest calibration file accepted, bytes (``edge.calibration.model.MAX_BYTES``).
    """

    def __init__(self, root, probe: str, policy: Any = None, *, parse: Callable[[bytes], StoredCalibration],
                 max_bytes: int) -> None:
        self.root = Path(root)
        self.probe = probe
        self.policy = policy
        self.parse = parse
        self.max_bytes = max_bytes
        if not self.root.is_dir():
            self.root.parent.mkdir(parents=True, exist_ok=True)
            durable.make_dir(self.root)
        for name in (FILE, SIGNATURE):
            durable.remove_stray_temporaries(self.root / name)

    def current(self) -> StoredCalibration | None:
        """The installed calibration, or None when there is none.

        Raises
        ------
        CalibrationStoreError
            The stored file is damaged or made for another probe.
        """
        path = self.root / FILE
        try:
            data = path.read_bytes()
        except FileNotFoundError:
            return None
        except OSError as e:
            raise CalibrationStoreError(f"cannot read {path}: {e.strerror}") from None
        try:
            cal = self.parse(data)
        except ValueError as e:
            raise CalibrationStoreError(f"stored calibration {path} is damaged: {e}") from None
        if cal.probe != self.probe:
            raise CalibrationStoreError(f"stored calibration is for probe {cal.probe!r}, this device is {self.probe!r}")
        return cal

    def install(self, blob: bytes, signature: bytes | None = None) -> StoredCalibration:
        """Verify ``blob`` (a calibration file) and make it the one in use.

        Raises
        ------
        CalibrationStoreError
            Naming the first check that failed; nothing on disk changes.
        """
        if len(blob) > self.max_bytes:
            raise CalibrationStoreError(f"calibration is {len(blob)} B, above the limit of {self.max_bytes} B")
        try:
            cal = self.parse(blob)
        except ValueError as e:
            raise CalibrationStoreError(f"calibration refused: {e}") from None
        if cal.probe != self.probe:
            raise CalibrationStoreError(f"calibration refused: made for probe {cal.probe!r}, this device is "
                                        f"{self.probe!r}")
        if not cal.calibrated:
            raise CalibrationStoreError("calibration refused: it is the uncalibrated datasheet chain")
        if self.policy is None:
            raise CalibrationStoreError("calibration refused: this device has no update policy")
        try:
            self.policy.authenticate(blob, signature)
        except UpdateRefused as e:
            raise CalibrationStoreError(f"calibration refused: {e}".replace("flash --key FILE",
                                                                            "calibrate --key FILE")) from None
        sig_path = self.root / SIGNATURE
        if signature is not None:
            durable.atomic_write_file(sig_path, signature)
        elif sig_path.exists():
            durable.remove_tree(sig_path)
            durable.fsync_dir(self.root)
        durable.atomic_write_file(self.root / FILE, blob)
        return cal

    def signed_by(self) -> str | None:
        """Key id of the installed calibration's signature (None: unsigned or none installed)."""
        try:
            from edge.security.keys import parse_signature  # noqa: PLC0415

            return parse_signature((self.root / SIGNATURE).read_bytes())[0]
        except Exception:
            return None
