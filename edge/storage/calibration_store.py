"""The probe's calibration on the device: one verified file, replaced atomically.

A calibration (:class:`edge.calibration.model.ProbeCalibration`) is a few kB of
JSON; the device keeps the one in use as ``calibration.json`` in its store
directory, with the signature it was installed with beside it, named by the
SHA-256 of the bytes it signed (``calibration.<sha256>.sig``).  Installing
checks, in order: size, UTF-8 JSON and every field (with the file's own
SHA-256), the probe it was made for against the device's, and the update
policy's signature rule over the exact bytes (as model bundles and object
sets).  Then the signature is written under the new bytes' hash, the bytes
with :func:`edge.storage.durable.atomic_write_file` (the one durable step: a
kill leaves the old calibration or the new one), and the signatures of other
bytes are dropped.  The signature in use is always the one named by the hash
of the calibration in use, so after a kill at any step the calibration and its
``signed_by`` agree (ISSUE #35 §9: with one ``calibration.sig`` written before
the bytes, a kill in between named the new signer beside the old bytes).
After the signature, an install is checked against what is installed and against this device
(ISSUE #35 §2): a calibration dated more than :data:`edge.security.policy.FUTURE_SLACK_s` after the device's clock is
refused (it would stay "newest" for years and block every real one); one not newer than the
installed calibration (``created_utc`` order, as models) is refused unless it is the same bytes'
calibration (a repeated install changes nothing); one naming another device (``device_id``) is
refused, and one naming none is accepted only where the policy allows unsigned updates (a strict
device takes only calibrations bound to it).  Reading back refuses a calibration naming another
device than this one.

Opening the store removes stray temporaries and signatures of other bytes, and
migrates an old ``calibration.sig`` (kept only if it verifies over the stored
bytes).  Reading back re-checks the fields and the checksum (a damaged file is
named, never used).

The store knows files, not what a calibration means: the caller gives it the
parser (``ProbeCalibration.from_json`` on the device, :mod:`edge.service.calibration`)
and the size bound, so storage does not import the calibration model above it.
"""

from __future__ import annotations

import hashlib
import logging
import os
import re
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Callable, Protocol

from edge.security.policy import UpdateRefused, check_version
from edge.storage import durable

__all__ = ["CalibrationStore", "CalibrationStoreError", "StoredCalibration"]

log = logging.getLogger("thermotouch.edge")

FILE = "calibration.json"
#: The signature file of earlier stores (whatever bytes it signed); migrated on open.
LEGACY_SIGNATURE = "calibration.sig"
#: A signature's file name: ``calibration.<sha256 of the bytes it signed>.sig``.
_SIG_RE = re.compile(r"^calibration\.([0-9a-f]{64})\.sig$")


def _utc_now() -> datetime:
    return datetime.now(timezone.utc)


class CalibrationStoreError(ValueError):
    """A calibration refused on install, or a stored one that cannot be read; the message says why."""


class StoredCalibration(Protocol):
    """What the store reads of a parsed calibration (:class:`edge.calibration.model.ProbeCalibration` has it)."""

    #: The probe head it was made for.
    probe: str
    #: False for the uncalibrated datasheet chain (never installed).
    calibrated: bool
    #: As written in the file.
    created_utc: str
    #: created_utc as an aware UTC datetime (raises ValueError when it cannot be ordered).
    created_time: datetime
    #: The device it was made for (None: not bound).
    device_id: str | None


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
    device_id : callable () -> str or None, optional
        This device's identity (the daemon's ``device_id``; None while it is unknown).
    now : callable () -> datetime, optional
        The device's clock (aware UTC datetime); default the system's.
    """

    def __init__(self, root, probe: str, policy: Any = None, *, parse: Callable[[bytes], StoredCalibration],
                 max_bytes: int, device_id: Callable[[], str | None] | None = None,
                 now: Callable[[], datetime] = _utc_now) -> None:
        self.device_id = device_id if device_id is not None else (lambda: None)
        self.now = now
        self.root = Path(root)
        self.probe = probe
        self.policy = policy
        self.parse = parse
        self.max_bytes = max_bytes
        if not self.root.is_dir():
            self.root.parent.mkdir(parents=True, exist_ok=True)
            durable.make_dir(self.root)
        self._clean()

    # -- signatures ----------------------------------------------------------------
    def _signature_path(self, sha256: str) -> Path:
        return self.root / f"calibration.{sha256}.sig"

    def _stored_sha256(self) -> str | None:
        try:
            return hashlib.sha256((self.root / FILE).read_bytes()).hexdigest()
        except OSError:
            return None

    def _clean(self) -> None:
        """Start-up: stray temporaries go, an old ``calibration.sig`` is migrated, other bytes' signatures go."""
        for entry in os.listdir(self.root):
            if entry.startswith(".calibration.") and ".tmp" in entry:
                durable.remove_tree(self.root / entry)
        sha = self._stored_sha256()
        legacy = self.root / LEGACY_SIGNATURE
        if os.path.lexists(legacy):
            self._migrate(legacy, sha)
        try:
            self._drop_signatures(keep=None if sha is None else self._signature_path(sha))
        except OSError as e:
            log.error("calibration store: cannot remove stale signatures: %s", e)

    def _migrate(self, legacy: Path, sha: str | None) -> None:
        """Keep an earlier store's ``calibration.sig`` only if it verifies over the stored bytes."""
        ok = False
        if sha is not None and self.policy is not None:
            try:
                ok = self.policy.authenticate((self.root / FILE).read_bytes(), legacy.read_bytes()).signed
            except (OSError, UpdateRefused):
                ok = False
        try:
            if ok:
                durable.replace(legacy, self._signature_path(sha))
            else:
                log.warning("calibration store: %s does not verify over the stored calibration; dropped",
                            LEGACY_SIGNATURE)
                os.unlink(legacy)
            durable.fsync_dir(self.root)
        except OSError as e:
            log.error("calibration store: cannot migrate %s: %s", LEGACY_SIGNATURE, e)

    def _drop_signatures(self, keep: Path | None) -> None:
        """Remove every signature file but ``keep`` (None: all)."""
        gone = False
        for entry in os.listdir(self.root):
            if _SIG_RE.match(entry) and self.root / entry != keep:
                os.unlink(self.root / entry)
                gone = True
        if gone:
            durable.fsync_dir(self.root)

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
        me = self.device_id()
        if cal.device_id is not None and me is not None and cal.device_id != me:
            raise CalibrationStoreError(f"stored calibration was made for device {cal.device_id}, this device is {me}")
        return cal

    def _check_against_installed(self, cal: StoredCalibration, blob: bytes) -> None:
        """Device binding, the clock and the order of calibrations (see the module docstring)."""
        me = self.device_id()
        if cal.device_id is not None:
            if me is None:
                raise CalibrationStoreError(f"calibration refused: it names device {cal.device_id} and this "
                                            "device's identity is unavailable")
            if cal.device_id != me:
                raise CalibrationStoreError(f"calibration refused: made for device {cal.device_id}, this device is "
                                            f"{me}")
        elif not getattr(self.policy, "allow_unsigned", False):
            raise CalibrationStoreError("calibration refused: it names no device (device_id); this device takes "
                                        "only calibrations made for it (thermotouch calibrate on it, or records "
                                        "exported from it)")
        try:
            new_t = cal.created_time
        except ValueError as e:
            raise CalibrationStoreError(f"calibration refused: {e}") from None
        try:
            old = self.current()
        except CalibrationStoreError:
            old = None   # a damaged or foreign stored file orders nothing: a good one replaces it
        old_t = None
        if old is not None and self._stored_sha256() != hashlib.sha256(blob).hexdigest() \
                and getattr(old, "sha256", None) != getattr(cal, "sha256", object()):
            try:
                old_t = old.created_time
            except ValueError:
                pass     # an installed file from before created_utc was checked cannot be ordered
        try:  # the rule shared with object sets (edge.security.policy.check_version)
            check_version("calibration", cal.created_utc, new_t, None if old is None else old.created_utc, old_t,
                          self.now())
        except UpdateRefused as e:
            raise CalibrationStoreError(f"calibration refused: {e}") from None

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
        self._check_against_installed(cal, blob)
        # The signature first, under the hash of the bytes it signs (never read beside other bytes),
        # then the bytes in one rename (the install's one durable step), then the other signatures.
        keep = None
        if signature is not None:
            keep = self._signature_path(hashlib.sha256(blob).hexdigest())
            durable.atomic_write_file(keep, bytes(signature))
        durable.atomic_write_file(self.root / FILE, blob)
        try:
            self._drop_signatures(keep)
        except OSError as e:  # the calibration is installed; a stale signature names no bytes in use
            log.error("calibration store: cannot remove stale signatures: %s", e)
        return cal

    def signed_by(self) -> str | None:
        """Key id of the installed calibration's signature (None: unsigned or none installed)."""
        from edge.security.keys import KeyFileError, parse_signature  # noqa: PLC0415

        sha = self._stored_sha256()
        if sha is None:
            return None
        try:
            return parse_signature(self._signature_path(sha).read_bytes())[0]
        except (OSError, KeyFileError):
            return None
