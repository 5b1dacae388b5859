"""Ed25519 signatures (RFC 8032, section 5.1) in pure Python: key generation, signing, verification.

Why pure Python
---------------
The probe's runtime must stay lean: NumPy and its I/O stack only. PyNaCl and
``cryptography`` ship binary wheels for aarch64 but not reliably for armv7
(the older boards build them from source, with a Rust or C toolchain) and add
megabytes to the install, while the device verifies one signature per update.
Python's integers and :mod:`hashlib`'s SHA-512 are all the curve arithmetic
needs; ``python bench/ed25519_bench.py`` measures the cost (import and verify
times in ``bench/results/ed25519.json``; a few milliseconds per verification
on a PC).

What it is and is not
---------------------
Written from the equations of RFC 8032 (twisted Edwards curve
-x² + y² = 1 + d x² y² over GF(2²⁵⁵ - 19), extended coordinates of
section 5.1.4). Verification follows section 5.1.7 strictly: the encodings of
R and A must decode to curve points (y < p, a square root exists, no "negative
zero"), S must be canonical (S < L, refusing the malleable S + L), and the
group equation is checked with the cofactor, [8][S]B = [8]R + [8][k]A.

Signing is not constant-time (Python integers are not), so a secret key
should only be used on the host that owns it, never on a machine where an
attacker can time it. The device only verifies, with public data.
"""

from __future__ import annotations

import hashlib

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

# The field prime, the group order and the curve constant d = -121665/121666 (RFC 8032, 5.1).
_P = 2**255 - 19
_L = 2**252 + 27742317777372353535851937790883648493
_D = (-121665 * pow(121666, _P - 2, _P)) % _P
_D2 = (2 * _D) % _P
# A square root of -1 mod p, used when the first square-root candidate is off by that factor.
_SQRT_M1 = pow(2, (_P - 1) // 4, _P)


class SignatureError(ValueError):
    """A key, signature or encoding is malformed (wrong length, not a curve point, S not canonical)."""


# ------------------------------------------------------------------ points (extended X, Y, Z, T)

_Point = tuple[int, int, int, int]
_IDENTITY: _Point = (0, 1, 1, 0)


def _add(p: _Point, q: _Point) -> _Point:
    """Point addition, RFC 8032 5.1.4 (complete: also right for p == q and the identity)."""
    x1, y1, z1, t1 = p
    x2, y2, z2, t2 = q
    a = (y1 - x1) * (y2 - x2) % _P
    b = (y1 + x1) * (y2 + x2) % _P
    c = t1 * _D2 * t2 % _P
    d = z1 * 2 * z2 % _P
    e, f, g, h = b - a, d - c, d + c, b + a
    return (e * f % _P, g * h % _P, f * g % _P, e * h % _P)


def _double(p: _Point) -> _Point:
    """Point doubling, RFC 8032 5.1.4 (cheaper than _add(p, p): four squarings instead of a T product)."""
    x1, y1, z1, _t1 = p
    a = x1 * x1 % _P
    b = y1 * y1 % _P
    c = 2 * z1 * z1 % _P
    h = a + b
    s = x1 + y1
    e = h - s * s % _P
    g = a - b
    f = c + g
    return (e * f % _P, g * h % _P, f * g % _P, e * h % _P)


def _neg(p: _Point) -> _Point:
    x, y, z, t = p
    return ((-x) % _P, y, z, (-t) % _P)


def _equal(p: _Point, q: _Point) -> bool:
    # Projective: x1/z1 == x2/z2 and y1/z1 == y2/z2 without inversions.
    return (p[0] * q[2] - q[0] * p[2]) % _P == 0 and (p[1] * q[2] - q[1] * p[2]) % _P == 0


def _mul(k: int, p: _Point) -> _Point:
    """[k]p by double-and-add from the top bit."""
    q = _IDENTITY
    for i in range(k.bit_length() - 1, -1, -1):
        q = _double(q)
        if (k >> i) & 1:
            q = _add(q, p)
    return q


def _mul2(a: int, p: _Point, b: int, q: _Point) -> _Point:
    """[a]p + [b]q with one shared chain of doublings (Straus/Shamir): verification's cost."""
    pq = _add(p, q)
    r = _IDENTITY
    for i in range(max(a.bit_length(), b.bit_length()) - 1, -1, -1):
        r = _double(r)
        bits = ((a >> i) & 1) | (((b >> i) & 1) << 1)
        if bits == 1:
            r = _add(r, p)
        elif bits == 2:
            r = _add(r, q)
        elif bits == 3:
            r = _add(r, pq)
    return r


def _recover_x(y: int, sign: int) -> int | None:
    """x from y and the sign bit (RFC 8032 5.1.3, step 2-4); None if no such point."""
    if y >= _P:
        return None
    u = (y * y - 1) % _P
    v = (_D * y * y + 1) % _P
    # Candidate root of u/v without an inversion: x = u v³ (u v⁷)^((p-5)/8).
    x = u * pow(v, 3, _P) * pow(u * pow(v, 7, _P), (_P - 5) // 8, _P) % _P
    vxx = v * x * x % _P
    if vxx == u:
        pass
    elif vxx == (-u) % _P:
        x = x * _SQRT_M1 % _P
    else:
        return None  # u/v is not a square: y is not on the curve
    if x == 0 and sign:
        return None  # "negative zero" is not a valid encoding
    if x & 1 != sign:
        x = _P - x
    return x


def _encode(p: _Point) -> bytes:
    x, y, z, _t = p
    zi = pow(z, _P - 2, _P)
    x, y = x * zi % _P, y * zi % _P
    return (y | ((x & 1) << 255)).to_bytes(32, "little")


def _decode(s: bytes, what: str) -> _Point:
    n = int.from_bytes(s, "little")
    y, sign = n & ((1 << 255) - 1), n >> 255
    x = _recover_x(y, sign)
    if x is None:
        raise SignatureError(f"{what} is not the encoding of a curve point")
    return (x, y, 1, x * y % _P)


_BY = 4 * pow(5, _P - 2, _P) % _P
_B: _Point = (_recover_x(_BY, 0), _BY, 1, _recover_x(_BY, 0) * _BY % _P)  # type: ignore[operator]


# ------------------------------------------------------------------ the scheme


def _h(*parts: bytes) -> int:
    return int.from_bytes(hashlib.sha512(b"".join(parts)).digest(), "little")


def _expand(secret: bytes) -> tuple[int, bytes]:
    """The secret scalar s (clamped, RFC 8032 5.1.5) and the nonce prefix."""
    h = hashlib.sha512(secret).digest()
    a = int.from_bytes(h[:32], "little")
    # Clamping: a multiple of the cofactor 8, and the top bit fixed so every key has the same length.
    a &= (1 << 254) - 8
    a |= 1 << 254
    return a, h[32:]


def _bytes(value: object, n: int, what: str) -> bytes:
    if not isinstance(value, (bytes, bytearray, memoryview)):
        raise SignatureError(f"{what} must be bytes, got {type(value).__name__}")
    value = bytes(value)
    if len(value) != n:
        raise SignatureError(f"{what} must be {n} bytes, got {len(value)}")
    return value


def generate_secret() -> bytes:
    """A new 32-byte secret key from the operating system's CSPRNG."""
    import secrets  # noqa: PLC0415 - only the host makes keys; the device's import stays lighter

    return secrets.token_bytes(SECRET_KEY_BYTES)


def public_key(secret: bytes) -> bytes:
    """The 32-byte public key of a 32-byte secret key (RFC 8032 5.1.5).

    Raises
    ------
    SignatureError
        ``secret`` is not 32 bytes.
    """
    secret = _bytes(secret, SECRET_KEY_BYTES, "secret key")
    a, _prefix = _expand(secret)
    return _encode(_mul(a, _B))


def sign(secret: bytes, message: bytes) -> bytes:
    """The 64-byte signature R || S of ``message`` (RFC 8032 5.1.6; deterministic).

    Raises
    ------
    SignatureError
        ``secret`` is not 32 bytes.
    """
    secret = _bytes(secret, SECRET_KEY_BYTES, "secret key")
    message = bytes(message)
    a, prefix = _expand(secret)
    pub = _encode(_mul(a, _B))
    r = _h(prefix, message) % _L
    r_enc = _encode(_mul(r, _B))
    k = _h(r_enc, pub, message) % _L
    s = (r + k * a) % _L
    return r_enc + s.to_bytes(32, "little")


def check_signature(public: bytes, message: bytes, signature: bytes) -> None:
    """Verify ``signature`` of ``message`` under ``public`` (RFC 8032 5.1.7), or raise.

    Raises
    ------
    SignatureError
        A wrong length, an encoding that is not a curve point, a non-canonical
        S (>= L), or a signature that does not verify; the message says which.
    """
    public = _bytes(public, PUBLIC_KEY_BYTES, "public key")
    signature = _bytes(signature, SIGNATURE_BYTES, "signature")
    message = bytes(message)
    a_pt = _decode(public, "public key")
    r_enc, s_enc = signature[:32], signature[32:]
    r_pt = _decode(r_enc, "signature R")
    s = int.from_bytes(s_enc, "little")
    if s >= _L:
        raise SignatureError("signature S is not canonical (S >= L)")
    k = _h(r_enc, public, message) % _L
    # [S]B - [k]A - R must be of small order: multiplying by the cofactor 8 gives the identity.
    q = _add(_mul2(s, _B, k, _neg(a_pt)), _neg(r_pt))
    q = _double(_double(_double(q)))
    if not _equal(q, _IDENTITY):
        raise SignatureError("signature does not verify")


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
