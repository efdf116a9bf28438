"""The text rule: which characters a name, label, frame id or source may hold.

Refused, because a consumer of what the service stores or exports refuses them:

- the C0 controls U+0000..U+001F and DEL U+007F (PostgreSQL cannot store NUL, logs must stay
  readable; no label needs a tab or a line break);
- lone surrogates U+D800..U+DFFF: halves of a UTF-16 pair, not characters; UTF-8, PostgreSQL and
  strict JSON parsers refuse them;
- the 66 non-characters: U+FDD0..U+FDEF and the last two code points of every plane (U+FFFE,
  U+FFFF, U+1FFFE, U+1FFFF, ... U+10FFFF). XML 1.0 forbids U+FFFE and U+FFFF outright, so one
  of them in a label made every GraphML export of its scene ill-formed.

`check_text` applies the rule to request bodies with a message naming the character.
`PRINTABLE` is the part of it a JSON Schema pattern states in every regular-expression dialect
(the BMP but the surrogates): the OpenAPI document carries it, and text query parameters are
checked with it (a query is compared, never stored; the supplementary planes' non-characters
pass there).
`replace_refused` is what the GraphML export does to text already stored by older versions.
"""

from __future__ import annotations

import re

from pydantic_core import PydanticCustomError

SURROGATES = (0xD800, 0xDFFF)
# Inclusive code point ranges, in order.
REFUSED_RANGES: tuple[tuple[int, int], ...] = (
    (0x00, 0x1F),
    (0x7F, 0x7F),
    SURROGATES,
    (0xFDD0, 0xFDEF),
    *((plane + 0xFFFE, plane + 0xFFFF) for plane in range(0, 0x110000, 0x10000)),
)
REPLACEMENT = "\ufffd"


def _escaped(code: int) -> str:
    """A code point as a regular-expression escape (`\\U` only Python's and Rust's engines read)."""
    if code < 0x100:
        return f"\\x{code:02x}"
    return f"\\u{code:04x}" if code <= 0xFFFF else f"\\U{code:08x}"


def _class_of(ranges: tuple[tuple[int, int], ...]) -> str:
    return "".join(
        _escaped(low) if low == high else f"{_escaped(low)}-{_escaped(high)}"
        for low, high in ranges
    )


_REFUSED = re.compile(f"[{_class_of(REFUSED_RANGES)}]")
# The BMP ranges but the surrogates: pydantic's pattern engine cannot name a surrogate, and
# refuses a string holding one before it matches any pattern.
_IN_PATTERNS = tuple(r for r in REFUSED_RANGES if r[1] <= 0xFFFF and r != SURROGATES)
PRINTABLE = f"^[^{_class_of(_IN_PATTERNS)}]*$"


def kind_of(character: str) -> str:
    """What a refused character is, for messages."""
    code = ord(character)
    if code < 0x20:
        return "a control character"
    if code == 0x7F:
        return "DEL"
    if 0xD800 <= code <= 0xDFFF:
        return "a lone surrogate"
    return "a non-character"


def first_refused(text: str) -> str | None:
    """The first character of `text` the rule refuses, or None."""
    found = _REFUSED.search(text)
    return found.group() if found else None


def check_text(value: object) -> object:
    """A pydantic before-validator: a string holding a refused character is an error naming it;
    anything else passes on to the field's own validation."""
    if isinstance(value, str):
        refused = first_refused(value)
        if refused is not None:
            raise PydanticCustomError(
                "refused_character",
                "text must not contain {character}, {kind} (control characters, DEL, lone "
                "surrogates and non-characters are refused)",
                {"character": f"U+{ord(refused):04X}", "kind": kind_of(refused)},
            )
    return value


def replace_refused(text: str) -> str:
    """`text` with every refused character replaced by U+FFFD (the replacement character)."""
    return _REFUSED.sub(REPLACEMENT, text)
