"""Flashing a model bundle onto a probe: verify locally, upload in chunks, confirm the device runs it."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from host.device import DeviceSession, DeviceUnavailable
from host.progress import ProgressBar

__all__ = ["BundleRefused", "load_verified", "load_signing_key", "flash_bundle"]


class BundleRefused(DeviceUnavailable):
    """A bundle fails its own checks on the host (exit status 2)."""

    def __init__(self, message: str) -> None:
        super().__init__(message, 2)


def load_verified(path: str | Path) -> Any:
    """Load a bundle directory with every check, including the pipeline golden vectors.

    Raises
    ------
    BundleRefused
        Naming the bundle and what is wrong with it.
    """
    from edge.model.bundle import BundleError, load_bundle  # noqa: PLC0415
    from edge.estimation.estimate import pipeline_golden_check  # noqa: PLC0415

    p = Path(path)
    if not p.is_dir():
        raise BundleRefused(f"bundle {p} refused: not a bundle directory")
    try:
        return load_bundle(p, golden_check=pipeline_golden_check)
    except BundleError as exc:
        raise BundleRefused(f"bundle {p} refused: {exc}") from None


def load_signing_key(path: str | Path | None) -> Any:
    """The secret key of ``--key FILE`` (None without one).

    Raises
    ------
    BundleRefused
        Unreadable or malformed key file, or a public one (exit status 2).
    """
    if path is None:
        return None
    from edge.security.keys import KeyFileError  # noqa: PLC0415
    from host.keys import load_secret_key  # noqa: PLC0415

    try:
        return load_secret_key(path)
    except KeyFileError as exc:
        raise BundleRefused(f"signing key refused: {exc}") from None


def flash_bundle(session: DeviceSession, path: str | Path, *, progress: bool = True, key: Any = None,
                 force: bool = False) -> dict:
    """Verify ``path``, upload it over the session's link and confirm the device reports its sha256.

    Parameters
    ----------
    key : edge.security.keys.SecretKey, optional
        Sign the manifest with it on the host; the signature travels with the upload
        (the bundle directory is not changed). Without it the bundle's own
        ``signature.json`` is sent if it has one, else the upload is unsigned.
    force : bool
        A deliberate rollback: sign, with ``key`` (required), an authorisation to install this
        bundle over the model the device runs now, and send it with the upload.

    Returns
    -------
    dict
        ``{"model_sha256", "model_version", "bytes", "previous_sha256"}``.

    Raises
    ------
    BundleRefused
        The bundle fails locally.
    DeviceUnavailable
        The device refuses it, does not answer, or reports another model afterwards.
    """
    from edge.model.bundle import BundleError, bundle_to_bytes  # noqa: PLC0415

    bundle = load_verified(path)
    signature = None
    if key is not None:
        from host.keys import sign_manifest  # noqa: PLC0415

        signature = sign_manifest(path, key)
    try:
        blob = bundle_to_bytes(path, signature=signature)
    except BundleError as exc:
        raise BundleRefused(f"bundle {path} refused: {exc}") from None
    c = session.client
    before = c.info().get("model_sha256")
    downgrade = None
    if force:
        if key is None:
            raise BundleRefused("--force needs --key: a rollback is authorised by a signature, not by a flag")
        if before is not None:
            from edge.security.keys import downgrade_document  # noqa: PLC0415

            downgrade = downgrade_document(key, bundle.sha256, before)
    with ProgressBar("flashing", "B", enabled=progress, unit_scale=True) as bar:
        c.upload_model(blob, progress=bar, version=bundle.model_version, downgrade=downgrade)
    now = c.info().get("model_sha256")
    if now != bundle.sha256:
        raise DeviceUnavailable(f"device reports model {now} after flashing {path}, expected {bundle.sha256}")
    return {"model_sha256": now, "model_version": bundle.model_version, "bytes": len(blob),
            "previous_sha256": before, "key_id": None if key is None else key.key_id}
