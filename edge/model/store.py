"""The probe's model store: verified, atomic model updates that survive a power cut.

Layout under ``root``::

    bundles/<sha256>/    one verified bundle per identity (sha256 of its manifest.json)
    current              pointer file: "<sha256>\\n" of the active bundle
    previous             pointer file: the bundle active before the last install
    tmp/                 staging for uploads; emptied at start-up

Pointers are replaced with write-temp / fsync / ``os.replace`` / fsync-dir, and a bundle
directory is complete and fsynced before any pointer names it, so after a crash at any point
the pointers name either the old or the new bundle, each intact. At boot the store tries
``current``, then ``previous``, then the factory bundle shipped with the software, each fully
verified (hashes, schema, golden vectors) before use.

Authenticity: an upload is installed only if the store's
:class:`~edge.security.policy.UpdatePolicy` accepts it -- a signature over the
manifest by a trusted key (or no signature where the policy allows unsigned
updates) and, for a signed update, a ``created_utc`` newer than the active
model's unless the upload carries a signed downgrade authorisation. A store without a policy refuses every
upload. Bundles already in the store (and the factory bundle, trusted by being
on the read-only install) are not re-authenticated at boot: only what comes
over the link is.
"""

from __future__ import annotations

import hashlib
import os
import re
import secrets
import threading
from pathlib import Path
from typing import Any, Callable

from edge.storage import durable
from edge.model.bundle import (
    DEFAULT_GOLDEN_RTOL,
    DEFAULT_LIMITS,
    Bundle,
    BundleError,
    GoldenCheck,
    Limits,
    MANIFEST_FILE,
    bundle_from_bytes,
    load_bundle,
    read_signature,
)
from edge.security.policy import UpdatePolicy, UpdateRefused

_HEX64 = re.compile(r"^[0-9a-f]{64}$")


class ModelStoreError(RuntimeError):
    """No usable model, or a store operation failed."""


class InstallError(ModelStoreError):
    """An upload was refused; the active model is unchanged. ``__cause__`` holds the detail."""


class ModelStore:
    """Device-side store of model bundles.

    Parameters
    ----------
    root : path-like
        Store directory (created if missing). Must be on one file system.
    factory_path : path-like, optional
        The shipped default bundle, used when neither ``current`` nor ``previous`` verifies.
    golden_check : callable
        Golden check run on every bundle before it is used or installed.
    golden_rtol : float
        Tolerance for the golden check.
    limits : edge.model.bundle.Limits
        Size bounds (the transport blob bound is ``limits.max_blob_bytes``).
    semantic_check : callable, optional
        ``semantic_check(bundle)`` raises ``ValueError`` (one-line message) if what an uploaded
        bundle decides is wrong (:func:`edge.estimation.selfcheck.semantic_check`; injected like
        the golden check because ``edge.model`` sits below ``edge.estimation``). Run on
        :meth:`install` only, after the golden check and before any pointer moves.
    policy : edge.security.policy.UpdatePolicy or None
        Which uploads :meth:`install` accepts (signatures, version floor).
        None: the store only loads, and refuses every upload.
    """

    CURRENT = "current"
    PREVIOUS = "previous"
    #: The downgrade authorisations used on this store (their SHA-256s, one a line): each works once.
    SPENT_DOWNGRADES = "downgrades.spent"

    def __init__(
        self,
        root: str | os.PathLike,
        factory_path: str | os.PathLike | None = None,
        *,
        golden_check: GoldenCheck,
        golden_rtol: float = DEFAULT_GOLDEN_RTOL,
        limits: Limits = DEFAULT_LIMITS,
        semantic_check: Callable[[Any], None] | None = None,
        policy: UpdatePolicy | None = None,
    ) -> None:
        self.root = Path(root)
        self.semantic_check = semantic_check
        self.policy = policy
        self.factory_path = Path(factory_path) if factory_path is not None else None
        self.golden_check = golden_check
        self.golden_rtol = golden_rtol
        self.limits = limits
        self.bundles_dir = self.root / "bundles"
        self.tmp_dir = self.root / "tmp"
        self._lock = threading.RLock()
        self._active: Bundle | None = None
        self.source: str | None = None
        """Where the active model came from: 'current', 'previous' or 'factory'."""
        self.boot_errors: list[str] = []
        self.last_authentication = None
        """How the last installed upload was authenticated (:class:`~edge.security.policy.Authentication`)."""
        """Why earlier candidates were skipped at the last boot (for the device log)."""
        for d in (self.root, self.bundles_dir, self.tmp_dir):
            if not d.is_dir():
                d.mkdir(parents=True, exist_ok=True)
                durable.fsync_dir(d.parent)
        self._clean_staging()

    # ---------------------------------------------------------------- pointers

    def _pointer_path(self, which: str) -> Path:
        return self.root / which

    def _read_pointer(self, which: str) -> str | None:
        """sha256 named by a pointer, None if absent; raises ModelStoreError if corrupt."""
        p = self._pointer_path(which)
        if not os.path.lexists(p):
            return None
        if p.is_symlink() or not p.is_file():
            raise ModelStoreError(f"pointer {which!r} is not a regular file")
        with open(p, "rb") as f:
            raw = f.read(129)
        try:
            text = raw.decode("ascii").strip()
        except UnicodeDecodeError:
            text = ""
        if not _HEX64.match(text):
            raise ModelStoreError(f"pointer {which!r} is corrupt ({raw[:80]!r})")
        return text

    def _write_pointer(self, which: str, sha: str) -> None:
        durable.atomic_write_file(self._pointer_path(which), (sha + "\n").encode("ascii"))

    def _bundle_path(self, sha: str) -> Path:
        return self.bundles_dir / sha

    def _load_verified(self, path: Path, expect_sha: str | None = None) -> Bundle:
        b = load_bundle(path, self.golden_check, golden_rtol=self.golden_rtol, limits=self.limits)
        if expect_sha is not None and b.sha256 != expect_sha:
            raise BundleError(f"bundle at {path} has identity {b.sha256}, pointer says {expect_sha}")
        return b

    def _clean_staging(self) -> None:
        # Leftovers of an interrupted upload or pointer write are never referenced.
        for entry in os.listdir(self.tmp_dir):
            durable.remove_tree(self.tmp_dir / entry)
        for entry in os.listdir(self.root):
            if entry.startswith(".") and ".tmp" in entry:
                durable.remove_tree(self.root / entry)
        # An install killed after moving its bundle into bundles/ but before ``current`` names it,
        # or while collecting the bundle it replaced, leaves bundles no pointer names (whole, or
        # half deleted). Nothing ever loads them; without this they stayed until the next install.
        # Only with a readable ``current``: a store whose pointer is lost keeps its bundles for a
        # person to look at (and ``_collect_garbage`` itself keeps everything if a pointer is corrupt).
        try:
            if self._read_pointer(self.CURRENT) is not None:
                self._collect_garbage()
        except ModelStoreError:
            pass

    # ---------------------------------------------------------------- boot

    def current(self) -> Bundle:
        """The active, verified bundle (loaded once, then cached).

        Tries ``current``, then ``previous``, then the factory bundle; the reasons for skipping
        a candidate are kept in :attr:`boot_errors`.

        Raises
        ------
        ModelStoreError
            If no candidate verifies.
        """
        with self._lock:
            if self._active is not None:
                return self._active
            errors: list[str] = []
            for which in (self.CURRENT, self.PREVIOUS):
                try:
                    sha = self._read_pointer(which)
                    if sha is None:
                        errors.append(f"{which}: no pointer")
                        continue
                    bundle = self._load_verified(self._bundle_path(sha), sha)
                except (ModelStoreError, BundleError, OSError) as e:
                    errors.append(f"{which}: {e}")
                    continue
                self._active, self.source, self.boot_errors = bundle, which, errors
                return bundle
            if self.factory_path is not None:
                try:
                    bundle = self._load_verified(self.factory_path)
                except (BundleError, OSError) as e:
                    errors.append(f"factory: {e}")
                else:
                    self._active, self.source, self.boot_errors = bundle, "factory", errors
                    return bundle
            else:
                errors.append("factory: no factory bundle configured")
            self.boot_errors = errors
            raise ModelStoreError("no usable model: " + "; ".join(errors))

    def status(self) -> dict:
        """Summary for logs/CLI: active source, identities and model versions."""
        with self._lock:
            out: dict = {"source": None, "sha256": None, "model_version": None, "boot_errors": []}
            try:
                b = self.current()
                out.update(source=self.source, sha256=b.sha256, model_version=b.model_version)
            except ModelStoreError as e:
                out["error"] = str(e)
            out["boot_errors"] = list(self.boot_errors)
            for which in (self.CURRENT, self.PREVIOUS):
                try:
                    out[f"{which}_pointer"] = self._read_pointer(which)
                except ModelStoreError as e:
                    out[f"{which}_pointer"] = f"corrupt: {e}"
            return out

    # ---------------------------------------------------------------- install

    def install(self, blob: bytes, expected_sha256: str, expected_size: int | None = None, *,
                downgrade: bytes | str | None = None) -> Bundle:
        """Verify and activate a bundle received as a transport blob.

        Steps: check size and sha256 of the blob; unpack into ``tmp/``; fsync; load with the
        golden check; authenticate the manifest's signature and check the version floor
        (:attr:`policy`); move into ``bundles/<identity>``; point ``previous`` at the model that
        was active; point ``current`` at the new one; drop unreferenced bundles.

        Parameters
        ----------
        blob : bytes
            Transport blob from :func:`edge.model.bundle.bundle_to_bytes`.
        expected_sha256 : str
            SHA-256 (hex) of ``blob`` as announced by the sender.
        expected_size : int, optional
            Announced length of ``blob`` in bytes.
        downgrade : bytes or str, optional
            A downgrade authorisation (:func:`edge.security.keys.downgrade_document`) that lets a
            signed bundle not newer than the active one be installed (a deliberate rollback);
            authentication is never skipped.

        Returns
        -------
        Bundle
            The newly active bundle.

        Raises
        ------
        InstallError
            Anything wrong; the active model is left unchanged.
        """
        with self._lock:
            staging = self.tmp_dir / f"upload-{secrets.token_hex(6)}"
            try:
                return self._install(blob, expected_sha256, expected_size, staging, downgrade)
            except InstallError:
                raise
            except UpdateRefused as e:
                raise InstallError(f"install refused, active model unchanged: {e}") from e
            except (BundleError, OSError, ValueError) as e:
                raise InstallError(f"install refused, active model unchanged: {e}") from e
            finally:
                durable.remove_tree(staging)

    def _install(self, blob: bytes, expected_sha256: str, expected_size: int | None, staging: Path,
                 downgrade: bytes | str | None) -> Bundle:
        if self.policy is None:
            raise InstallError("install refused: this model store has no update policy (it only loads models)")
        if not isinstance(expected_sha256, str) or not _HEX64.match(expected_sha256.lower()):
            raise InstallError("expected_sha256: must be 64 hex digits")
        if len(blob) > self.limits.max_blob_bytes:
            raise InstallError(f"blob is {len(blob)} bytes, above the limit of {self.limits.max_blob_bytes}")
        if expected_size is not None and len(blob) != expected_size:
            raise InstallError(f"blob size mismatch: announced {expected_size} bytes, received {len(blob)}")
        got = hashlib.sha256(blob).hexdigest()
        if got != expected_sha256.lower():
            raise InstallError(f"blob sha256 mismatch: announced {expected_sha256.lower()}, received {got}")

        # Who is active now decides what "previous" becomes.
        try:
            active: Bundle | None = self.current()
            active_source = self.source
        except ModelStoreError:
            active, active_source = None, None

        bundle_from_bytes(blob, staging, self.limits)
        new = self._load_verified(staging)
        # The signature covers the exact manifest bytes received (their sha256 is the identity).
        with open(staging / MANIFEST_FILE, "rb") as f:
            manifest_bytes = f.read(self.limits.max_manifest_bytes + 1)
        if hashlib.sha256(manifest_bytes).hexdigest() != new.sha256:
            raise InstallError("manifest changed while installing")
        auth = self.policy.authenticate(manifest_bytes, read_signature(staging))
        used = self.policy.check_newer(new.manifest, new.sha256, None if active is None else active.manifest,
                                       None if active is None else active.sha256, auth=auth, downgrade=downgrade)
        spent = None
        if used is not None:
            # An authorisation names one (new, active) pair; a model can run again later (v3 -> v2
            # -> v3), so the pair alone would let a replay repeat the rollback: each is used once.
            spent = hashlib.sha256(downgrade.encode("utf-8") if isinstance(downgrade, str) else downgrade).hexdigest()
            if spent in self._spent_downgrades():
                raise InstallError("install refused, active model unchanged: this downgrade authorisation "
                                   "was used before (sign a new one)")
        self.last_authentication = auth
        self._check_semantics(new)
        target = self._bundle_path(new.sha256)
        if os.path.lexists(target):
            try:
                self._load_verified(target, new.sha256)
            except (BundleError, OSError):
                # A damaged copy of the same identity: swap in the fresh one.
                trash = self.tmp_dir / f"trash-{secrets.token_hex(6)}"
                durable.rename_dir(target, trash)
                durable.rename_dir(staging, target)
                durable.fsync_dir(self.tmp_dir)
            # else: identical verified bundle already stored
        else:
            durable.rename_dir(staging, target)
        durable.fsync_dir(self.bundles_dir)

        if spent is not None:
            # Spent before the switch: an install killed in between leaves it spent and the old model
            # running (the operator signs another), never a reusable authorisation.
            durable.atomic_write_file(self.root / self.SPENT_DOWNGRADES,
                                      "".join(f"{h}\n" for h in sorted(self._spent_downgrades() | {spent})).encode())
        if active is not None and active_source in (self.CURRENT, self.PREVIOUS) and active.sha256 != new.sha256:
            self._write_pointer(self.PREVIOUS, active.sha256)
        self._write_pointer(self.CURRENT, new.sha256)

        self._active, self.source, self.boot_errors = self._load_verified(target, new.sha256), self.CURRENT, []
        self._collect_garbage()
        return self._active

    def _spent_downgrades(self) -> set[str]:
        """SHA-256s of the downgrade authorisations already used on this store."""
        try:
            text = (self.root / self.SPENT_DOWNGRADES).read_text("ascii")
        except FileNotFoundError:
            return set()
        return {line for line in text.split() if _HEX64.match(line)}

    def _check_semantics(self, bundle: Bundle) -> None:
        # Before the bundle is stored or named by a pointer: a refusal leaves the store as it was.
        if self.semantic_check is None:
            return
        try:
            self.semantic_check(bundle)
        except (ValueError, ArithmeticError) as e:
            raise InstallError(f"install refused, active model unchanged: semantic self-check: {e}") from e

    def rollback(self) -> Bundle:
        """Make ``previous`` current again (after verifying it); the two pointers swap.

        Raises
        ------
        ModelStoreError
            No previous bundle, or it does not verify.
        """
        with self._lock:
            prev = self._read_pointer(self.PREVIOUS)
            if prev is None:
                raise ModelStoreError("rollback: no previous model")
            try:
                bundle = self._load_verified(self._bundle_path(prev), prev)
            except (BundleError, OSError) as e:
                raise ModelStoreError(f"rollback: previous model does not verify: {e}") from e
            try:
                cur = self._read_pointer(self.CURRENT)
            except ModelStoreError:
                cur = None
            # current first: a crash in between leaves both pointing at the verified bundle.
            self._write_pointer(self.CURRENT, prev)
            if cur is not None and cur != prev:
                self._write_pointer(self.PREVIOUS, cur)
            self._active, self.source, self.boot_errors = bundle, self.CURRENT, []
            return bundle

    def _collect_garbage(self) -> None:
        keep = set()
        for which in (self.CURRENT, self.PREVIOUS):
            try:
                sha = self._read_pointer(which)
            except ModelStoreError:
                return  # cannot tell what is referenced; keep everything
            if sha:
                keep.add(sha)
        for entry in os.listdir(self.bundles_dir):
            if entry not in keep:
                durable.remove_tree(self.bundles_dir / entry)
        for entry in os.listdir(self.tmp_dir):
            durable.remove_tree(self.tmp_dir / entry)
