"""Terminal output conventions shared by every command.

Colour only on a terminal and only when the user has not asked for none: the `NO_COLOR`
convention (https://no-color.org): set and not empty means no ANSI colour, whatever its
value. Textual applies the same variable to the TUI itself (a monochrome filter).
"""

from __future__ import annotations

import os
import sys


def color_enabled(stream=None) -> bool:
    """True when `stream` (default stdout) is a terminal and NO_COLOR is unset or empty."""
    stream = sys.stdout if stream is None else stream
    if os.environ.get("NO_COLOR"):
        return False
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


def plot_text(plt, text: str, stream=None) -> str:
    """A built plotext figure as it should be printed: ANSI colours removed unless allowed."""
    return text if color_enabled(stream) else plt.uncolorize(text)
