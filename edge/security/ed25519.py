"""Ed25519 signatures (RFC 8032): key generation, signing, verification, through ``cryptography``.

Why ``cryptography``
--------------------
A signature check is the one thing between the link and the device's model,
calibration and object sets, so it rests on a maintained, audited, constant-time
implementation (OpenSSL's, through the ``cryptography`` package, which ships
wheels for aarch64 and armv7 Raspberry Pi OSes) rather than on curve arithmetic
of our own; the project's earlier pure-Python RFC 8032 code is gone (ISSUE #35).
This module is the one place the project touches it: the rest of the code calls
the five functions below with plain bytes, so keys and signatures stay the
small JSON documents of :mod:`edge.security.keys`.

Verification is strict: OpenSSL refuses encodings that are not curve points and
a non-canonical S (S >= L, the malleable S + L); this module names the lengths
and the S bound itself, so the common refusals say why.
"""

from __future__ import annotations

from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey, Ed25519PublicKey
from cryptography.hazmat.primitives.serialization import Encoding, PublicFormat

__all__ = [
    "PUBLIC_KEY_BYTES",
    "SECRET_KEY_BYTES",
    "SIGNATURE_BYTES",
    "SignatureError",
    "generate_secret",
    "public_key",
    "sign",
    "verify",
    "check_signature",
]

#: Lengths fixed by RFC 8032 (bytes).
PUBLIC_KEY_BYTES = 32
SECRET_KEY_BYTES = 32
SIGNATURE_BYTES = 64
#: The order of the base point (RFC 8032 5.1): a canonical S is below it.
_L = 2**252 + 27742317777372353535851937790883648493


class SignatureError(ValueError):
    """A key or signature is malformed, or a signature does not verify (the message says which)."""


def _bytes(value: object, n: int, what: str) -> bytes:
    if not isinstance(value, (bytes, bytearray, memoryview)):
        raise SignatureError(f"{what} must be bytes, got {type(value).__name__}")
    value = bytes(value)
    if len(value) != n:
        raise SignatureError(f"{what} must be {n} bytes, got {len(value)}")
    return value


def generate_secret() -> bytes:
    """A new 32-byte secret key (the RFC 8032 seed) from the operating system's CSPRNG."""
    import secrets  # noqa: PLC0415 - only the host makes keys

    return secrets.token_bytes(SECRET_KEY_BYTES)


def public_key(secret: bytes) -> bytes:
    """The 32-byte public key of a 32-byte secret key (RFC 8032 5.1.5).

    Raises
    ------
    SignatureError
        ``secret`` is not 32 bytes.
    """
    sk = Ed25519PrivateKey.from_private_bytes(_bytes(secret, SECRET_KEY_BYTES, "secret key"))
    return sk.public_key().public_bytes(Encoding.Raw, PublicFormat.Raw)


def sign(secret: bytes, message: bytes) -> bytes:
    """The 64-byte signature R || S of ``message`` (RFC 8032 5.1.6; deterministic).

    Raises
    ------
    SignatureError
        ``secret`` is not 32 bytes.
    """
    sk = Ed25519PrivateKey.from_private_bytes(_bytes(secret, SECRET_KEY_BYTES, "secret key"))
    return sk.sign(bytes(message))


def check_signature(public: bytes, message: bytes, signature: bytes) -> None:
    """Verify ``signature`` of ``message`` under ``public`` (RFC 8032 5.1.7), or raise.

    Raises
    ------
    SignatureError
        A wrong length, a non-canonical S (>= L), a public key that is not a
        curve point, or a signature that does not verify; the message says which.
    """
    public = _bytes(public, PUBLIC_KEY_BYTES, "public key")
    signature = _bytes(signature, SIGNATURE_BYTES, "signature")
    if int.from_bytes(signature[32:], "little") >= _L:
        raise SignatureError("signature S is not canonical (S >= L)")
    try:
        pk = Ed25519PublicKey.from_public_bytes(public)
    except ValueError:
        raise SignatureError("public key is not the encoding of a curve point") from None
    try:
        pk.verify(signature, bytes(message))
    except InvalidSignature:
        raise SignatureError("signature does not verify") from None


def verify(public: bytes, message: bytes, signature: bytes) -> bool:
    """Whether ``signature`` of ``message`` verifies under ``public``.

    Malformed input (wrong length, not a point, S >= L) is False here; call
    :func:`check_signature` for the reason.
    """
    try:
        check_signature(public, message, signature)
    except SignatureError:
        return False
    return True
