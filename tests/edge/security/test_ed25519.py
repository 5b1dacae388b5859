"""Ed25519 against RFC 8032 section 7.1 (vectors typed in from the RFC) and the ways a forgery is refused."""

from __future__ import annotations

import hashlib

import pytest

from edge.security import ed25519 as E

# RFC 8032, 7.1: (SECRET KEY, PUBLIC KEY, MESSAGE, SIGNATURE), hex.
RFC8032_VECTORS = {
    "TEST 1": (
        "9d61b19deffd5a60ba844af492ec2cc44449c5697b326919703bac031cae7f60",
        "d75a980182b10ab7d54bfed3c964073a0ee172f3daa62325af021a68f707511a",
        "",
        "e5564300c360ac729086e2cc806e828a84877f1eb8e5d974d873e065224901555fb8821590a33bacc61e39701cf9b46bd25bf5f0595bbe24655141438e7a100b",
    ),
    "TEST 2": (
        "4ccd089b28ff96da9db6c346ec114e0f5b8a319f35aba624da8cf6ed4fb8a6fb",
        "3d4017c3e843895a92b70aa74d1b7ebc9c982ccf2ec4968cc0cd55f12af4660c",
        "72",
        "92a009a9f0d4cab8720e820b5f642540a2b27b5416503f8fb3762223ebdb69da085ac1e43e15996e458f3613d0f11d8c387b2eaeb4302aeeb00d291612bb0c00",
    ),
    "TEST 3": (
        "c5aa8df43f9f837bedb7442f31dcb7b166d38535076f094b85ce3a2e0b4458f7",
        "fc51cd8e6218a1a38da47ed00230f0580816ed13ba3303ac5deb911548908025",
        "af82",
        "6291d657deec24024827e69c3abe01a30ce548a284743a445e3680d7db5ac3ac18ff9b538d16f290ae67f760984dc6594a7c15e9716ed28dc027beceea1ec40a",
    ),
    "TEST SHA(abc)": (
        "833fe62409237b9d62ec77587520911e9a759cec1d19755b7da901b96dca3d42",
        "ec172b93ad5e563bf4932c70e1245034c35467ef2efd4d64ebf819683467e2bf",
        "ddaf35a193617abacc417349ae20413112e6fa4e89a97ea20a9eeee64b55d39a2192992a274fc1a836ba3c23a3feebbd454d4423643ce80e2a9ac94fa54ca49f",
        "dc2a4459e7369633a52b1bf277839a00201009a3efbf3ecb69bea2186c26b58909351fc9ac90b3ecfdfbc7c66431e0303dca179c138ac17ad9bef1177331a704",
    ),
}

# The group order (RFC 8032 5.1), to build a non-canonical S.
L = 2**252 + 27742317777372353535851937790883648493


def _vec(name):
    sk, pk, msg, sig = RFC8032_VECTORS[name]
    return bytes.fromhex(sk), bytes.fromhex(pk), bytes.fromhex(msg), bytes.fromhex(sig)


def test_sha_abc_message_is_sha512_of_abc():
    # The vector's message is the SHA-512 of "abc": a check on the typed-in hex itself.
    assert _vec("TEST SHA(abc)")[2] == hashlib.sha512(b"abc").digest()


@pytest.mark.parametrize("name", sorted(RFC8032_VECTORS))
def test_rfc8032_vectors_public_key_signature_and_verify(name):
    sk, pk, msg, sig = _vec(name)
    assert E.public_key(sk) == pk
    assert E.sign(sk, msg) == sig
    assert E.verify(pk, msg, sig)
    E.check_signature(pk, msg, sig)  # no exception


def _flip(b: bytes, bit: int) -> bytes:
    out = bytearray(b)
    out[bit // 8] ^= 1 << (bit % 8)
    return bytes(out)


@pytest.mark.parametrize("bit", [0, 7, 100])
def test_flipped_message_bit_is_refused(bit):
    sk, pk, msg, sig = _vec("TEST SHA(abc)")
    assert not E.verify(pk, _flip(msg, bit), sig)
    with pytest.raises(E.SignatureError, match="does not verify"):
        E.check_signature(pk, _flip(msg, bit), sig)


@pytest.mark.parametrize("bit", [0, 200, 256, 300, 500])
def test_flipped_signature_bit_is_refused(bit):
    sk, pk, msg, sig = _vec("TEST 3")
    assert not E.verify(pk, msg, _flip(sig, bit))


@pytest.mark.parametrize("bit", [0, 9, 128, 254])
def test_flipped_public_key_bit_is_refused(bit):
    sk, pk, msg, sig = _vec("TEST 2")
    assert not E.verify(_flip(pk, bit), msg, sig)


def test_key_of_another_signer_is_refused():
    _, pk1, _, _ = _vec("TEST 1")
    sk2, _, msg, sig2 = _vec("TEST 2")
    assert not E.verify(pk1, msg, sig2)


def test_non_canonical_s_is_refused():
    # S + L satisfies the group equation too (malleability); RFC 8032 5.1.7 requires S < L.
    sk, pk, msg, sig = _vec("TEST 1")
    s = int.from_bytes(sig[32:], "little")
    forged = sig[:32] + (s + L).to_bytes(32, "little")
    with pytest.raises(E.SignatureError, match=r"S is not canonical"):
        E.check_signature(pk, msg, forged)
    assert not E.verify(pk, msg, forged)


def test_encodings_that_are_not_points_are_refused():
    sk, pk, msg, sig = _vec("TEST 1")
    # y = p (not reduced) is not a valid encoding; y = 2 has no x on the curve.
    # OpenSSL (through cryptography) refuses both; it does not say which part failed to decode.
    y_p = (2**255 - 19).to_bytes(32, "little")
    with pytest.raises(E.SignatureError, match="not the encoding of a curve point|does not verify"):
        E.check_signature(y_p, msg, sig)
    not_on_curve = (2).to_bytes(32, "little")
    with pytest.raises(E.SignatureError, match="not the encoding of a curve point|does not verify"):
        E.check_signature(pk, msg, not_on_curve + sig[32:])


@pytest.mark.parametrize(
    "what, args, message",
    [
        ("public", (b"\x00" * 31, b"m", b"\x00" * 64), "public key must be 32 bytes, got 31"),
        ("signature", (b"\x00" * 32, b"m", b"\x00" * 63), "signature must be 64 bytes, got 63"),
        ("signature", (b"\x00" * 32, b"m", b"\x00" * 65), "signature must be 64 bytes, got 65"),
        ("type", (b"\x00" * 32, b"m", "00" * 64), "signature must be bytes, got str"),
    ],
)
def test_wrong_lengths_are_refused_with_a_clear_error(what, args, message):
    with pytest.raises(E.SignatureError, match=message):
        E.check_signature(*args)
    assert not E.verify(*args)


def test_secret_key_length_is_checked():
    with pytest.raises(E.SignatureError, match="secret key must be 32 bytes, got 33"):
        E.sign(b"\x01" * 33, b"m")
    with pytest.raises(E.SignatureError, match="secret key must be 32 bytes"):
        E.public_key(b"")


def test_generated_key_round_trip():
    sk = E.generate_secret()
    pk = E.public_key(sk)
    sig = E.sign(sk, b"manifest bytes")
    assert E.verify(pk, b"manifest bytes", sig)
    assert not E.verify(pk, b"manifest bytez", sig)
