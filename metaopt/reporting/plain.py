"""User text in the terminal (names, labels, paths, settings, messages), shown as typed.

rich reads a str as markup and emoji codes, and its ``escape`` is right only before a tag: a
trailing backslash it doubles shows doubled ('C:\\runs\\' as 'C:\\runs\\\\'), and ':cd:' is
still an emoji. A Text is never read, so user text reaches rich as one, from ``plain``."""

from __future__ import annotations

from rich.style import StyleType
from rich.text import Text


def plain(text: str, style: StyleType = "") -> Text:
    """``text`` exactly as typed (no markup, no emoji codes), in ``style``."""
    return Text(text, style=style)


def table_title(text: str) -> Text:
    """A table's title as typed: rich styles only a str title as one, so a Text gives it the
    style itself."""
    return plain(text, "table.title")
