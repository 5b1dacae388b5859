"""Text for the fuzz tests from a fixed alphabet, not Hypothesis's default one.

``st.text()``'s default alphabet is every Unicode code point outside the surrogates: Hypothesis builds
its table of categories for that on first use and keeps it in ``.hypothesis/`` -- about 1 CPU-s in
each process of a clean checkout (CI's), for code points the protocol treats alike.  What the
decoders must survive is here: every byte value as a character (ASCII controls, the JSON quote and
backslash, Latin-1), and characters of each longer UTF-8 length (Greek, CJK, the byte-order mark,
the replacement character, a noncharacter, an emoji, the last code point).
"""

ALPHABET = "".join(map(chr, range(0x100))) + "\u0100\u0391\u4e2d\ufeff\ufffd\uffff\U0001f600\U0010ffff"


def text(max_size: int):
    """``st.text`` of at most ``max_size`` characters of :data:`ALPHABET`."""
    from hypothesis import strategies as st

    return st.text(alphabet=ALPHABET, max_size=max_size)
