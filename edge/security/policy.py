"""What the device accepts as an update: who must have signed it, and that it is newer than what runs.

Authentication
--------------
An update carries a detached Ed25519 signature over its manifest bytes
(:data:`edge.security.keys.SIGNATURE_FILE`). It is accepted only if the
signature's key is among the public key files in ``trusted_keys_dir`` and the
signature verifies. An unsigned update is refused unless ``allow_unsigned``
(a development device). A signature that is present is always checked, even
where unsigned updates are allowed: a bad or untrusted signature is a sign of
tampering or of the wrong key, never silently ignored.

Version ordering (downgrade protection)
---------------------------------------
Updates are ordered by the manifest's ``created_utc`` (ISO 8601,
``YYYY-MM-DDTHH:MM:SSZ``; every bundle has it, ``thermotouch train`` writes
it when it builds the bundle). A signed update that is not strictly newer than
the active model is refused unless the upload carries a downgrade
authorisation (:func:`edge.security.keys.downgrade_document`): a document
signed by a trusted key that names the bundle to install and the model it may
replace. Re-sending the active bundle itself is not a version change and is
accepted. This stops a replay of an old, legitimately signed bundle with a
known flaw: nobody on the link can ask for the downgrade by a flag (an
unauthenticated ``force`` once did exactly that), and an authorisation, being
addressed to one active model, is spent as soon as another model runs.

The floor is applied to authenticated updates only: for an unsigned upload
(allowed on a development device) ``created_utc`` is whatever the sender
wrote, so comparing it would stop nobody and only get in the developer's way.

The factory bundle is trusted by being on the read-only install, not by a
signature; it is never installed through this policy.

Calibrations and object sets are ordered the same way, by their own
``created_utc``, with one rule (:func:`check_version`): refused when dated
more than :data:`FUTURE_SLACK_s` after the device's clock (it would stay
"newest" for years and block every real one), and refused when not strictly
newer than the newest installed of its kind (a replay of an older, legitimately
signed file). Neither has a downgrade authorisation: an older calibration or
set is re-issued (signed again, with a new ``created_utc``).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Mapping

from edge.security import ed25519
from edge.security.keys import (KeyFileError, PublicKey, downgrade_message, load_trusted_keys, parse_downgrade,
                                 parse_signature)

__all__ = ["UpdateRefused", "UpdatePolicy", "Authentication", "release_time", "check_version", "FUTURE_SLACK_s"]

log = logging.getLogger("thermotouch.edge")

_TIME_FORMAT = "%Y-%m-%dT%H:%M:%SZ"
#: How far an update's created_utc may lie after the device's clock (s): a day covers time zones
#: and a device whose clock has not been set by NTP yet, not a file dated years ahead.
FUTURE_SLACK_s = 86400.0


class UpdateRefused(ValueError):
    """An update failed authentication or the version floor; the message says which, on one line."""


@dataclass(frozen=True)
class Authentication:
    """Outcome of :meth:`UpdatePolicy.authenticate`: the signer's key id, or None for an allowed unsigned update."""

    key_id: str | None

    @property
    def signed(self) -> bool:
        return self.key_id is not None

    def describe(self) -> str:
        return f"signed by key {self.key_id}" if self.signed else "unsigned (allowed on this device)"


def release_time(manifest: Mapping[str, Any], what: str) -> datetime:
    """The manifest's ``created_utc`` as an aware datetime (the order of updates).

    Raises
    ------
    UpdateRefused
        Missing or not ``YYYY-MM-DDTHH:MM:SSZ``.
    """
    text = manifest.get("created_utc")
    try:
        return datetime.strptime(str(text), _TIME_FORMAT).replace(tzinfo=timezone.utc)
    except ValueError:
        raise UpdateRefused(f"{what} created_utc {text!r} is not YYYY-MM-DDTHH:MM:SSZ; "
                            "cannot order it against the active model") from None


def check_version(what: str, created_utc: str, new_t: datetime, installed_utc: str | None,
                  installed_t: datetime | None, now: datetime) -> None:
    """The version rule of calibrations and object sets: not in the future, strictly newer than the installed.

    Parameters
    ----------
    what : str
        The kind, in messages ("calibration", "object set").
    created_utc, new_t : str, datetime
        The update's ``created_utc`` as written and as an aware UTC datetime.
    installed_utc, installed_t : str or None, datetime or None
        The newest installed of this kind (None: nothing to be newer than).
    now : datetime
        The device's clock (aware UTC).

    Raises
    ------
    UpdateRefused
        Dated more than :data:`FUTURE_SLACK_s` ahead of ``now``, or not newer than the installed one.
    """
    if (new_t - now).total_seconds() > FUTURE_SLACK_s:
        raise UpdateRefused(f"created_utc {created_utc} is in the future (device clock "
                            f"{now.strftime(_TIME_FORMAT)})")
    if installed_t is not None and new_t <= installed_t:
        raise UpdateRefused(f"created {created_utc}, not newer than the installed one ({installed_utc}); an older "
                            f"{what} is not re-installed")


@dataclass(frozen=True)
class UpdatePolicy:
    """The device's rules for accepting an update.

    Parameters
    ----------
    trusted_keys_dir : str or None
        Directory of public key files (``thermotouch keys new`` writes them);
        read at each install, so adding a key needs no restart. None or ''
        trusts no key.
    allow_unsigned : bool
        Accept updates without a signature (development devices only).
    """

    trusted_keys_dir: str | None = None
    allow_unsigned: bool = False

    def trusted_keys(self) -> dict[str, PublicKey]:
        """The trusted public keys by key id (files that do not parse are logged and skipped)."""
        if not self.trusted_keys_dir:
            return {}
        keys, skipped = load_trusted_keys(Path(self.trusted_keys_dir))
        for why in skipped:
            log.warning("trusted keys: %s", why)
        return keys

    def authenticate(self, manifest_bytes: bytes, signature_doc: bytes | None) -> Authentication:
        """Check an update's signature over its manifest bytes.

        Parameters
        ----------
        manifest_bytes : bytes
            The exact bytes of ``manifest.json``.
        signature_doc : bytes or None
            The bytes of ``signature.json``; None when the update has none.

        Raises
        ------
        UpdateRefused
            Unsigned where that is not allowed, malformed signature, unknown
            key, or a signature that does not verify.
        """
        if signature_doc is None:
            if self.allow_unsigned:
                return Authentication(None)
            raise UpdateRefused("unsigned update refused: this device accepts only updates signed by a trusted key "
                                "(thermotouch flash --key FILE)")
        try:
            kid, sig = parse_signature(signature_doc)
        except KeyFileError as e:
            raise UpdateRefused(f"signature refused: {e}") from None
        self._verify(kid, manifest_bytes, sig, "signature", "manifest changed after signing?")
        return Authentication(kid)

    def _verify(self, kid: str, message: bytes, sig: bytes, what: str, hint: str) -> None:
        keys = self.trusted_keys()
        key = keys.get(kid)
        if key is None:
            where = self.trusted_keys_dir or "(no trusted_keys_dir configured)"
            raise UpdateRefused(f"{what} by untrusted key {kid} refused: not among the {len(keys)} trusted "
                                f"key(s) in {where}")
        try:
            ed25519.check_signature(key.public, message, sig)
        except ed25519.SignatureError as e:
            raise UpdateRefused(f"bad {what} by key {kid}: {e} ({hint})") from None

    def authorise_downgrade(self, document: bytes | str, new_sha256: str, active_sha256: str) -> str:
        """Check a downgrade authorisation for installing ``new_sha256`` over ``active_sha256``; its key id.

        Raises
        ------
        UpdateRefused
            Malformed, for another pair of models, by an untrusted key, or not verifying.
        """
        try:
            kid, to, frm, sig = parse_downgrade(document)
        except KeyFileError as e:
            raise UpdateRefused(f"downgrade authorisation refused: {e}") from None
        if to != new_sha256 or frm != active_sha256:
            raise UpdateRefused(f"downgrade authorisation refused: it allows {to[:12]}... over {frm[:12]}..., "
                                f"not {new_sha256[:12]}... over the active {active_sha256[:12]}...")
        self._verify(kid, downgrade_message(to, frm), sig, "downgrade authorisation",
                     "signed for other models?")
        return kid

    def check_newer(self, new_manifest: Mapping[str, Any], new_sha256: str,
                    active_manifest: Mapping[str, Any] | None, active_sha256: str | None, *,
                    auth: Authentication, downgrade: bytes | str | None = None) -> str | None:
        """Refuse a signed update that is not newer than the active model, unless a downgrade is authorised.

        See the module docstring for the rule and why unsigned updates skip it.

        Parameters
        ----------
        downgrade : bytes or str, optional
            A downgrade authorisation (:func:`edge.security.keys.downgrade_document`); checked
            only when the update is not newer.

        Returns
        -------
        str or None
            The key id of the downgrade authorisation this install needed and used (None: none
            was needed). The caller keeps it from being used twice (the model store does).

        Raises
        ------
        UpdateRefused
            Not newer and not authorised, or a ``created_utc`` that cannot be ordered.
        """
        if not auth.signed or active_manifest is None or new_sha256 == active_sha256:
            return None
        new_t = release_time(new_manifest, "update")
        old_t = release_time(active_manifest, "active model")
        if new_t <= old_t:
            if downgrade is not None:
                kid = self.authorise_downgrade(downgrade, new_sha256, str(active_sha256))
                log.warning("downgrade to %s authorised by key %s", new_sha256[:12], kid)
                return kid
            raise UpdateRefused(
                f"downgrade refused: update {new_manifest.get('model_version')!r} created "
                f"{new_t.strftime(_TIME_FORMAT)} is not newer than the active "
                f"{active_manifest.get('model_version')!r} created {old_t.strftime(_TIME_FORMAT)} "
                "(a rollback needs a signed authorisation: thermotouch flash --force --key FILE)")
        return None

