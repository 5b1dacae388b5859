"""The probe's object sets: verified uploads, stored atomically, one of them active, surviving restarts.

Layout under ``root``::

    sets/<name>.csv   one verified object-set CSV per name (the bytes as uploaded)
    sets/<name>.<sha256 of the bytes>.sig   the signature those bytes came with, if any
    active            pointer file: "<name>\\n" of the active set; absent = the built-in library
    pending           the install under way: {"name", "sha256", "activate"} (absent between installs)
    version           the newest signed set installed: {"created_utc", "sha256"} (see Versions)
    verified          {sha256: object count} of the bytes this store verified (see Work per request)

Every write goes through :mod:`edge.storage.durable`: a set file is written
to a temporary sibling, fsynced and renamed over its name, and the pointer
the same way, so after a power cut at any step each name holds either its
old or its new bytes, and the pointer names a set that was complete when it
was written. An upload is checked completely (:func:`verify_upload`) before
anything is written: a bad one changes nothing.

An install is all or nothing, signature and activation included (ISSUE #35
§9). The signature is written first, under the hash of the bytes it signs
(it can never name the signer of other bytes); then ``pending`` records what
the install is (name, hash, whether it activates); then the set file is
renamed into place -- the install's commit point; then the pointer, then
the other signatures go and ``pending`` with them. Opening the store after
a kill finishes an install whose bytes are in place (the pointer is
written if it asked for activation) and forgets one whose bytes are not
(the old set, its signature and the old pointer stand); signatures of bytes
no set holds are removed.

Versions (ISSUE #35 §2, as calibrations and models): a signed set carries its
release time in a comment line before its header, ``# created_utc:
YYYY-MM-DDTHH:MM:SSZ`` (``thermotouch objects add --key`` writes it), and is
refused unless strictly newer than every signed set this store installed
(the ``version`` file keeps the newest: its time and sha256; removing a set
does not lower it) and not dated in the future
(:func:`edge.security.policy.check_version`, the rule calibrations follow).
Re-sending the newest set's own bytes is no version change and is accepted.
The floor applies to signed sets only: an unsigned upload (allowed on a
development device) dates itself as its sender likes, as for models. The
floor is written before the set's bytes, so a cut install can only raise it.

Work per request (ISSUE #35 §7): the serve loop answers OBJECTS_LIST and
commits uploads on its own thread, so neither may cost more than a fraction
of ``WatchdogSec``. A set is parsed once, when it is installed (or, for bytes
stored before ``verified`` existed, at its first listing); the object count of
every verified byte string is kept in ``verified`` by its sha256 (written
before the set's bytes, pruned to the stored sets), so OBJECTS_LIST reads and
hashes each stored set (at most :data:`MAX_SETS` x :data:`MAX_SET_BYTES`) and
parses none whose bytes it verified; a commit parses its upload once and the
active set is never parsed again for it.

What an object set *is* (the CSV format) is not known here: the parser is
injected (``parse``; the daemon passes
:meth:`edge.recognition.ObjectSet.from_csv_text`), as the model store
takes its golden check -- storage stays below estimation.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import re
import threading
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Callable

from edge.security.policy import UpdateRefused, check_version, release_time
from edge.storage import durable

__all__ = ["MAX_SET_BYTES", "MAX_SETS", "NAME_RE", "RESERVED_NAMES", "ObjectStoreError", "UploadRefused",
           "StoredSet", "verify_upload", "check_name", "set_created_utc", "ObjectSetStore"]

log = logging.getLogger("thermotouch.edge")

#: Largest object-set CSV accepted, bytes (about 3000 objects; held in memory until verified).
MAX_SET_BYTES = 256 * 1024
#: Most object sets stored at once (bounds the storage an upload can take).
MAX_SETS = 16
#: A set's name: a file name on every file system, no path, no hidden file.
NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$")
#: Names that are not stored sets: the built-in library (the default set).
RESERVED_NAMES = frozenset({"library"})

#: The version line of a set: ``# created_utc: YYYY-MM-DDTHH:MM:SSZ`` before the header.
_CREATED_RE = re.compile(r"^#\s*created_utc\s*[:=]\s*(\S+)\s*$")
#: A sha256 in hex.
_SHA_RE = re.compile(r"^[0-9a-f]{64}$")
#: What follows "<name>." in a signature's file name.
_SIG_RE = re.compile(r"^[0-9a-f]{64}\.sig$")
#: ``parse(text, label) -> object set`` (raises ValueError for a malformed set).
Parser = Callable[[str, str], Any]


class ObjectStoreError(RuntimeError):
    """A store operation failed (unknown name, full store, I/O); the stored sets are unchanged."""


class UploadRefused(ObjectStoreError):
    """An uploaded set failed verification; nothing was written."""


@dataclass(frozen=True)
class StoredSet:
    """One verified stored set: its name, the sha256 of its bytes, its size and the parsed set."""

    name: str
    sha256: str
    size: int
    objects: Any


def check_name(name: str) -> str:
    """``name`` if it can name a stored set, else :class:`ObjectStoreError` saying why."""
    if not isinstance(name, str) or not NAME_RE.match(name):
        raise ObjectStoreError(f"set name {name!r} must be 1-64 letters, digits, '.', '_' or '-', "
                               "starting with a letter or digit")
    if name in RESERVED_NAMES:
        raise ObjectStoreError(f"set name {name!r} is reserved for the built-in library")
    return name


def verify_upload(blob: bytes, expected_sha256: str, expected_size: int | None, *, name: str, parse: Parser,
                  max_bytes: int = MAX_SET_BYTES, policy: Any = None, signature: bytes | None = None,
                  authenticate: bool = True) -> Any:
    """Every check an uploaded object set must pass before it is stored; returns the parsed set.

    The one place an upload is judged: size bound, announced size, sha256
    of the bytes, the signature over them (the model updates' policy), UTF-8
    text, then the CSV parser with its line-and-column messages.

    Parameters
    ----------
    blob : bytes
        The uploaded file.
    expected_sha256 : str
        Hex digest announced by the sender.
    expected_size : int, optional
        Announced length, bytes.
    name : str
        The set's name (in messages).
    parse : callable
        ``parse(text, label)`` -> object set; raises ValueError when malformed.
    max_bytes : int
        Largest set accepted.
    policy : edge.security.policy.UpdatePolicy, optional
        Who may send updates (signed by a trusted key, or unsigned where
        allowed). None: every upload is refused, as by a model store
        without a policy.
    signature : bytes, optional
        ``signature.json`` over ``blob``.
    authenticate : bool
        False for a set read back from the device's own store: it was
        authenticated when it was installed (as a stored model bundle is).

    Raises
    ------
    UploadRefused
        Naming the first check that failed.
    """
    if len(blob) > max_bytes:
        raise UploadRefused(f"object set {name!r} is {len(blob)} B, above the limit of {max_bytes} B")
    if expected_size is not None and len(blob) != expected_size:
        raise UploadRefused(f"object set {name!r}: announced {expected_size} B, received {len(blob)} B")
    got = hashlib.sha256(blob).hexdigest()
    if got != str(expected_sha256).lower():
        raise UploadRefused(f"object set {name!r}: sha256 mismatch, announced {expected_sha256}, received {got}")
    if authenticate and policy is None:
        raise UploadRefused(f"object set {name!r} refused: this device has no update policy")
    try:
        if authenticate:
            policy.authenticate(blob, signature)
    except UpdateRefused as e:
        raise UploadRefused(f"object set {name!r}: {e}".replace("flash --key FILE", "objects add --key FILE")) \
            from None
    try:
        text = blob.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise UploadRefused(f"object set {name!r} is not UTF-8 text (byte {e.start})") from None
    try:
        return parse(text, name)
    except ValueError as e:
        # The parser's message lists every problem with its line and column; one line travels best.
        detail = "; ".join(line.strip() for line in str(e).splitlines() if line.strip())
        raise UploadRefused(f"object set {name!r} refused: {detail}") from None


def set_created_utc(blob: bytes) -> str | None:
    """The ``# created_utc:`` of a set's CSV bytes (comment lines before its header), or None."""
    for raw in blob[:8192].decode("utf-8-sig", errors="replace").splitlines():
        line = raw.strip()
        if not line:
            continue
        if not line.startswith("#"):
            return None  # the header: a version line comes before it
        m = _CREATED_RE.match(line)
        if m:
            return m.group(1)
    return None


def _utc_now() -> datetime:
    return datetime.now(timezone.utc)


class ObjectSetStore:
    """Device-side store of object sets, with one active set (or none: the built-in library).

    Parameters
    ----------
    root : path-like
        Store directory (created if missing).
    parse : callable
        ``parse(text, label)`` -> object set (raises ValueError when malformed).
    max_bytes : int
        Largest set accepted.
    max_sets : int
        Most sets stored.
    policy : edge.security.policy.UpdatePolicy, optional
        Who may send sets (None: uploads are refused).
    now : callable () -> datetime, optional
        The device's clock (aware UTC datetime); default the system's.
    """

    ACTIVE = "active"
    PENDING = "pending"
    VERSION = "version"
    VERIFIED = "verified"

    def __init__(self, root: str | os.PathLike, parse: Parser, *, max_bytes: int = MAX_SET_BYTES,
                 max_sets: int = MAX_SETS, policy: Any = None, now: Callable[[], datetime] = _utc_now) -> None:
        self.root = Path(root)
        self.now = now
        #: Who may send sets (:class:`edge.security.policy.UpdatePolicy`; None: uploads are refused).
        self.policy = policy
        self.sets_dir = self.root / "sets"
        self.parse = parse
        self.max_bytes = int(max_bytes)
        self.max_sets = int(max_sets)
        self._lock = threading.RLock()
        self._active: StoredSet | None = None
        self._loaded = False
        #: Why the active pointer could not be followed at the last load (the library is used meanwhile).
        self.error: str | None = None
        for d in (self.root, self.sets_dir):
            if not d.is_dir():
                d.mkdir(parents=True, exist_ok=True)
                durable.fsync_dir(d.parent)
        self._clean_temporaries()
        self._migrate_signatures()
        self._finish_pending()
        self._drop_orphan_signatures()
        #: sha256 -> object count of the bytes verified by this store (the ``verified`` file's copy).
        self._verified: dict[str, int] = self._read_verified()

    def _migrate_signatures(self) -> None:
        """Earlier stores kept ``<name>.sig`` whatever bytes it signed: keep one only if it verifies over them."""
        for name in self.names():
            old = self.sets_dir / f"{name}.sig"
            if not os.path.lexists(old):
                continue
            try:
                blob, sig = self._set_path(name).read_bytes(), old.read_bytes()
                ok = self.policy is not None and self.policy.authenticate(blob, sig).signed
            except (OSError, UpdateRefused):
                ok = False
            try:
                if ok:
                    durable.replace(old, self._signature_path(name, hashlib.sha256(blob).hexdigest()))
                else:
                    log.warning("object set %r: its signature file does not verify over its bytes; dropped", name)
                    os.unlink(old)
                durable.fsync_dir(self.sets_dir)
            except OSError as e:
                log.error("object set %r: cannot migrate its signature file: %s", name, e)

    def _finish_pending(self) -> None:
        """Start-up after a kill: complete the install whose bytes are in place, forget one whose bytes are not."""
        p = self.root / self.PENDING
        if not os.path.lexists(p):
            return
        try:
            doc = json.loads(p.read_bytes()[:4096])
            name, sha, activate = check_name(doc["name"]), str(doc["sha256"]), bool(doc["activate"])
        except (OSError, ValueError, KeyError, TypeError, ObjectStoreError) as e:
            log.warning("object store: unreadable pending install dropped (%s)", e)
            name = sha = None
            activate = False
        try:
            if name is not None:
                try:
                    stored = hashlib.sha256(self._set_path(name).read_bytes()).hexdigest()
                except FileNotFoundError:
                    stored = None
                if stored == sha:  # past the commit point: finish what the request asked
                    if activate and self._pointer_or_none() != name:
                        durable.atomic_write_file(self.root / self.ACTIVE, (name + "\n").encode("ascii"))
                    self._drop_signatures(name, keep=self._signature_path(name, sha))
                    log.warning("object set %r: install cut by a restart, completed%s", name,
                                ", active" if activate else "")
                else:
                    log.warning("object set %r: install cut before its bytes were stored, forgotten", name)
            os.unlink(p)
            durable.fsync_dir(self.root)
        except OSError as e:
            log.error("object store: cannot finish the pending install: %s", e)

    def _pointer_or_none(self) -> str | None:
        try:
            return self._read_pointer()
        except (ObjectStoreError, OSError):
            return None

    def _drop_orphan_signatures(self) -> None:
        """Signatures of bytes no stored set holds (left by a cut install) go at start-up."""
        held: dict[str, str | None] = {}
        try:
            for entry in sorted(os.listdir(self.sets_dir)):
                if not entry.endswith(".sig") or len(entry) < 70 or not _SIG_RE.match(entry[-68:]):
                    continue
                name, sha = entry[:-69], entry[-68:-4]
                if name not in held:
                    try:
                        held[name] = hashlib.sha256(self._set_path(name).read_bytes()).hexdigest()
                    except OSError:
                        held[name] = None
                if held[name] != sha:
                    os.unlink(self.sets_dir / entry)
                    log.info("object store: signature %s names no stored bytes; removed", entry)
            durable.fsync_dir(self.sets_dir)
        except OSError as e:
            log.error("object store: cannot remove orphan signatures: %s", e)

    # -- versions ----------------------------------------------------------------------
    def version_floor(self) -> tuple[str, str] | None:
        """``(created_utc, sha256)`` of the newest signed set installed (None: none yet)."""
        try:
            doc = json.loads((self.root / self.VERSION).read_bytes()[:4096])
            return str(doc["created_utc"]), str(doc["sha256"])
        except FileNotFoundError:
            return None
        except (OSError, ValueError, KeyError, TypeError) as e:
            # Written in one atomic step, so only outside damage gets here; it is named, not fatal.
            log.error("object store: version file unreadable (%s); no floor until the next signed set", e)
            return None

    def _check_version(self, name: str, blob: bytes, sha: str) -> dict:
        """The floor a signed set must clear (module docstring); the new floor to write."""
        created = set_created_utc(blob)
        if created is None:
            raise UploadRefused(f"object set {name!r} refused: a signed set names its version in a line "
                                "'# created_utc: YYYY-MM-DDTHH:MM:SSZ' before its header (thermotouch objects "
                                "add --key writes it)")
        try:
            new_t = release_time({"created_utc": created}, f"object set {name!r}")
            floor = self.version_floor()
            old_t = None
            if floor is not None and floor[1] != sha:  # the newest set's own bytes again: no version change
                old_t = release_time({"created_utc": floor[0]}, "installed object set")
            check_version("object set", created, new_t, None if floor is None else floor[0], old_t, self.now())
        except UpdateRefused as e:
            raise UploadRefused(f"object set {name!r} refused: {e}") from None
        return {"created_utc": created, "sha256": sha}

    # -- verified bytes ------------------------------------------------------------------
    def _read_verified(self) -> dict[str, int]:
        try:
            doc = json.loads((self.root / self.VERIFIED).read_bytes()[:65536])
            return {str(k): int(v) for k, v in doc.items() if _SHA_RE.match(str(k))}
        except FileNotFoundError:
            return {}
        except (OSError, ValueError, TypeError, AttributeError) as e:
            log.error("object store: %s unreadable (%s); sets are parsed again when listed", self.VERIFIED, e)
            return {}

    def _hashes(self) -> dict[str, str]:
        """sha256 of each stored set's bytes (unreadable ones left out)."""
        out = {}
        for name in self.names():
            try:
                out[name] = hashlib.sha256(self._set_path(name).read_bytes()).hexdigest()
            except OSError:
                pass
        return out

    def _write_verified(self, sha: str, count: int) -> None:
        """Add ``sha`` (the install's bytes), keeping only the bytes stored sets hold (the file stays small)."""
        held = set(self._hashes().values())
        doc = {k: v for k, v in self._verified.items() if k in held}
        doc[sha] = int(count)
        if doc != self._verified:
            durable.atomic_write_file(self.root / self.VERIFIED, json.dumps(doc, sort_keys=True).encode("ascii"))
        self._verified = doc

    # -- paths -----------------------------------------------------------------------
    def _set_path(self, name: str) -> Path:
        return self.sets_dir / f"{name}.csv"

    def _signature_path(self, name: str, sha256: str) -> Path:
        # Beside the set, not a set itself (names() lists *.csv only), and named by the bytes it
        # signed: a crash between writing a set and its signature can leave an orphan signature, never
        # one that names the wrong signer of the bytes stored (ISSUE #35 §9).
        return self.sets_dir / f"{name}.{sha256}.sig"

    def _signatures(self, name: str) -> list[Path]:
        return [self.sets_dir / e for e in os.listdir(self.sets_dir)
                if e.startswith(name + ".") and e.endswith(".sig") and _SIG_RE.match(e[len(name) + 1:])]

    def signed_by(self, name: str, sha: str | None = None) -> str | None:
        """Key id that signed the stored bytes of set ``name`` (None: uploaded unsigned, or unreadable).

        ``sha``: the stored bytes' sha256 when the caller has just hashed them.
        """
        from edge.security.keys import KeyFileError, parse_signature  # noqa: PLC0415

        try:
            if sha is None:
                sha = hashlib.sha256(self._set_path(name).read_bytes()).hexdigest()
            return parse_signature(self._signature_path(name, sha).read_bytes())[0]
        except (OSError, KeyFileError):
            return None

    def _drop_signatures(self, name: str, keep: Path | None = None) -> None:
        """Remove ``name``'s signatures of other bytes (and every one when ``keep`` is None)."""
        gone = False
        for p in self._signatures(name):
            if p != keep:
                os.unlink(p)
                gone = True
        if gone:
            durable.fsync_dir(self.sets_dir)

    def _clean_temporaries(self) -> None:
        # Leftovers of a write cut by a crash are never named by anything.
        for d in (self.root, self.sets_dir):
            for entry in os.listdir(d):
                if entry.startswith(".") and ".tmp" in entry:
                    durable.remove_tree(d / entry)

    def _read_pointer(self) -> str | None:
        p = self.root / self.ACTIVE
        if not os.path.lexists(p):
            return None
        if p.is_symlink() or not p.is_file():
            raise ObjectStoreError("active pointer is not a regular file")
        raw = p.read_bytes()[:129]
        try:
            name = raw.decode("ascii").strip()
        except UnicodeDecodeError:
            name = ""
        return check_name(name)

    def _load(self, name: str) -> StoredSet:
        """Read and re-verify a stored set (a stored file that no longer parses is refused)."""
        p = self._set_path(check_name(name))
        try:
            blob = p.read_bytes()
        except FileNotFoundError:
            raise ObjectStoreError(f"no object set {name!r}") from None
        except OSError as e:
            raise ObjectStoreError(f"object set {name!r} unreadable: {e}") from None
        sha = hashlib.sha256(blob).hexdigest()
        try:
            objs = verify_upload(blob, sha, len(blob), name=name, parse=self.parse, max_bytes=self.max_bytes,
                                 authenticate=False)
        except UploadRefused as e:
            raise ObjectStoreError(f"stored {e}") from None
        return StoredSet(name, sha, len(blob), objs)

    # -- reading ---------------------------------------------------------------------
    def names(self) -> list[str]:
        """Names of the stored sets, sorted."""
        out = []
        for entry in os.listdir(self.sets_dir):
            stem, dot, ext = entry.rpartition(".")
            if dot and ext == "csv" and NAME_RE.match(stem) and stem not in RESERVED_NAMES:
                out.append(stem)
        return sorted(out)

    def active(self) -> StoredSet | None:
        """The active stored set, or None for the built-in library.

        Loaded once and cached. A pointer that names a missing or corrupt set
        is reported in :attr:`error` and the library is used: a device must
        still name objects after a damaged card.
        """
        with self._lock:
            if not self._loaded:
                self._active, self.error = None, None
                try:
                    name = self._read_pointer()
                    if name is not None:
                        self._active = self._load(name)
                except (ObjectStoreError, OSError) as e:
                    self.error = f"active object set unusable, using the library: {e}"
                    log.error("%s", self.error)
                self._loaded = True
            return self._active

    def listing(self) -> list[dict]:
        """Every stored set: ``name``, ``sha256``, ``size``, ``objects`` (count), ``active``; or its ``error``.

        Bytes this store verified are not parsed again (module docstring, Work per request); others
        (stored before ``verified`` existed, or changed on the card) are, and a set that no longer
        parses is listed with its ``error``.
        """
        with self._lock:
            act = self.active()
            out = []
            for name in self.names():
                try:
                    blob = self._set_path(name).read_bytes()
                except OSError as e:
                    out.append({"name": name, "error": f"object set {name!r} unreadable: {e}", "active": False})
                    continue
                sha = hashlib.sha256(blob).hexdigest()
                count = self._verified.get(sha)
                if count is None:
                    try:
                        count = len(self._load(name).objects)
                    except ObjectStoreError as e:
                        out.append({"name": name, "error": str(e), "active": False})
                        continue
                    self._verified[sha] = count  # in memory: a listing writes nothing
                out.append({"name": name, "sha256": sha, "size": len(blob), "objects": count,
                            "active": act is not None and act.name == name, "signed_by": self.signed_by(name, sha)})
            return out

    # -- changing --------------------------------------------------------------------
    def install(self, name: str, blob: bytes, expected_sha256: str, expected_size: int | None = None, *,
                activate: bool = True, signature: bytes | None = None) -> StoredSet:
        """Verify an uploaded set, store it under ``name`` (replacing one of that name), optionally activate it.

        Nothing is written unless every check passes; the set file is durable
        before the pointer names it.

        Raises
        ------
        UploadRefused
            The set fails verification, or the name is unusable.
        ObjectStoreError
            The store is full or a write failed: the previous state stays, unless the set's bytes were
            already in place (then the install is finished here, or at the next opening of the store).
        """
        try:
            check_name(name)
        except ObjectStoreError as e:
            raise UploadRefused(str(e)) from None
        objs = verify_upload(blob, expected_sha256, expected_size, name=name, parse=self.parse,
                             max_bytes=self.max_bytes, policy=self.policy, signature=signature)
        with self._lock:
            existing = self.names()
            if name not in existing and len(existing) >= self.max_sets:
                raise ObjectStoreError(f"{len(existing)} object sets stored, the most this device keeps; "
                                       "remove one first")
            sha = hashlib.sha256(blob).hexdigest()
            version = None if signature is None else self._check_version(name, blob, sha)
            try:
                # The version floor and the signature first (the signature under the bytes' own hash);
                # then what the install is; then the bytes (the commit point: a restart finishes the
                # install from here on), the pointer, and the old signatures and the record go.
                sig = None
                if signature is not None:
                    if version is not None and self.version_floor() != (version["created_utc"], sha):
                        durable.atomic_write_file(self.root / self.VERSION, json.dumps(version).encode("ascii"))
                    sig = self._signature_path(name, sha)
                    durable.atomic_write_file(sig, bytes(signature))
                self._write_verified(sha, len(objs))
                durable.atomic_write_file(self.root / self.PENDING, json.dumps(
                    {"name": name, "sha256": sha, "activate": bool(activate)}).encode("ascii"))
                durable.atomic_write_file(self._set_path(name), bytes(blob))
                if activate:
                    durable.atomic_write_file(self.root / self.ACTIVE, (name + "\n").encode("ascii"))
                self._drop_signatures(name, keep=sig)
                os.unlink(self.root / self.PENDING)
                durable.fsync_dir(self.root)
            except OSError as e:
                self._finish_pending()  # past the commit point: finish now if the disk lets us
                self._loaded = False
                raise ObjectStoreError(f"cannot store object set {name!r}: {e}") from None
            stored = StoredSet(name, sha, len(blob), objs)
            if activate or (self._loaded and self._active is not None and self._active.name == name):
                # Active now, or the active set's bytes were replaced: the parse just done is its content
                # (a reload would parse it again on the serve loop).
                self._active, self.error, self._loaded = stored, None, True
            log.info("object set %r stored (%d objects, sha256 %s)%s", name, len(objs), stored.sha256[:12],
                     ", active" if activate else "")
            return stored

    def select(self, name: str | None) -> StoredSet | None:
        """Make ``name`` the active set (verified first); None or ``"library"``: the built-in library.

        Raises
        ------
        ObjectStoreError
            No such set, or it does not verify (the active set is unchanged).
        """
        with self._lock:
            if name is None or name in RESERVED_NAMES:
                self._clear_pointer()
                return None
            s = self._load(name)
            try:
                durable.atomic_write_file(self.root / self.ACTIVE, (name + "\n").encode("ascii"))
            except OSError as e:
                raise ObjectStoreError(f"cannot select object set {name!r}: {e}") from None
            self._active, self.error, self._loaded = s, None, True
            log.info("object set %r active", name)
            return s

    def _clear_pointer(self) -> None:
        p = self.root / self.ACTIVE
        try:
            if os.path.lexists(p):
                os.unlink(p)
                durable.fsync_dir(self.root)
        except OSError as e:
            raise ObjectStoreError(f"cannot switch to the library: {e}") from None
        self._active, self.error, self._loaded = None, None, True
        log.info("object set: the built-in library is active")

    def remove(self, name: str) -> bool:
        """Delete a stored set; returns whether it was the active one (then the library is active).

        The pointer is cleared before the file goes, so a crash in between
        leaves the library active and an unreferenced file, never a pointer
        to nothing.

        Raises
        ------
        ObjectStoreError
            No such set, or the delete failed.
        """
        with self._lock:
            check_name(name)
            p = self._set_path(name)
            if not p.is_file():
                raise ObjectStoreError(f"no object set {name!r}")
            try:
                was_active = self._read_pointer() == name
            except ObjectStoreError:
                was_active = False
            if was_active:
                self._clear_pointer()
            try:
                os.unlink(p)
                self._drop_signatures(name)
                durable.fsync_dir(self.sets_dir)
            except OSError as e:
                raise ObjectStoreError(f"cannot remove object set {name!r}: {e}") from None
            log.info("object set %r removed%s", name, " (was active; the library is active now)" if was_active
                     else "")
            return was_active
