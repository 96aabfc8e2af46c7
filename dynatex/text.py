"""Text for the terminal: names and attributes read from files, escaped before they are printed.

A leaf module (it imports nothing of ours), so the command line and every subcommand share it.
"""

from __future__ import annotations

import unicodedata


def printable(text: object) -> str:
    """``text`` with control and format characters escaped (``\\x1b``, ``\\u202e``): a name or
    attribute read from a file must not drive the terminal (set its title, clear it, reorder text).

    >>> printable("sea\\x1b]0;owned\\x07")
    'sea\\\\x1b]0;owned\\\\x07'
    """
    return "".join(
        c if unicodedata.category(c) not in ("Cc", "Cf") else c.encode("unicode_escape").decode("ascii")
        for c in str(text)
    )


__all__ = ["printable"]
