"""Input echoed in messages, made safe for a terminal: one line, no control characters.

Scene files and command lines are untrusted: a value written back in an error message must not
move the cursor, recolour the terminal, ring the bell, start a new line or reorder the text.
"""
from __future__ import annotations

import unicodedata

MAX_ECHO = 200   # characters of a value shown in a message; longer values end in "... (N characters)"

# Unicode categories a terminal acts on or cannot show: controls (C0, DEL, C1), format characters
# (the bidi overrides and isolates U+202A-202E, U+2066-2069, the marks, zero-width characters),
# surrogates, private use, unassigned, line and paragraph separators.
UNSAFE = ("Cc", "Cf", "Cs", "Co", "Cn", "Zl", "Zp")


def _escaped(char: str) -> str:
    """``char`` itself, or a Python-style escape (\\x1b, \\n, \\u202e) when a terminal would act on it."""
    if unicodedata.category(char) in UNSAFE:
        return char.encode("unicode_escape").decode("ascii")
    return char


def printable(value: object, limit: int = MAX_ECHO) -> str:
    """``value`` as text for a message: every control character (C0, DEL, C1), format character
    (bidi overrides, zero-width) and line or paragraph separator escaped as in Python (\\x1b,
    \\n, \\u202e), so the text stays on one line and shows what was given; at most ``limit``
    characters of the value."""
    text = value if isinstance(value, str) else str(value)
    shown = "".join(map(_escaped, text[:limit]))
    return shown if len(text) <= limit else f"{shown}... ({len(text)} characters)"
