"""Text from devices, captures and the database made safe for a terminal: one function.

Device ids, models, notes, operators, hosts, a capture's ``# device:`` line and warnings
are stored verbatim (quotes, SQL, Unicode, newlines), but a terminal would *act* on some
of their characters: ESC starts CSI/OSC sequences (colours, cursor moves, window titles,
hyperlinks, clipboard writes), BEL rings, CR and backspace overwrite what is shown, C1
bytes (U+0080..U+009F) are 8-bit CSI/OSC on some terminals, bidirectional overrides
reorder what is read, and a newline inside a field forges a table row.

:func:`safe` shows every such character escaped, Python style (``\\x1b``, ``\\n``,
``\\u202e``), and leaves all other text (accents, CJK, emoji, quotes, backslashes) as is.
Every command's text output and every TUI table goes through it; as a last line of
defence, :class:`SafeStream` applies the same escaping to anything else written to
stdout/stderr by a command (keeping the line breaks the command itself writes).
"""

from __future__ import annotations

import contextlib
import io
import re
import unicodedata

from station.errors import OutputError

_NAMED = {"\n": "\\n", "\r": "\\r", "\t": "\\t"}


def _unsafe(ch: str) -> bool:
    o = ord(ch)
    if o < 0x20 or 0x7F <= o <= 0x9F:
        return True
    if o < 0xA0:
        return False
    # format characters (bidi overrides and isolates, zero-width joiners used to hide text),
    # line/paragraph separators, surrogates and private use left unassigned
    return unicodedata.category(ch) in ("Cf", "Zl", "Zp", "Cs", "Cn")


# Precompiled class for the common range; rarer Unicode categories are checked per char.
_FAST = re.compile(r"[\x00-\x1f\x7f-\x9f]|[^\x00-\x9f]")


def _escape(ch: str) -> str:
    if ch in _NAMED:
        return _NAMED[ch]
    o = ord(ch)
    if o <= 0xFF:
        return f"\\x{o:02x}"
    if o <= 0xFFFF:
        return f"\\u{o:04x}"
    return f"\\U{o:08x}"


def safe(value, *, keep_newlines: bool = False) -> str:
    """``value`` as text with every terminal-active character shown escaped.

    ``keep_newlines``: leave ``\\n`` (and ``\\t``) alone, for multi-line text the station
    itself composed; fields (ids, names, notes) always get them escaped so that they
    cannot forge rows.
    """
    text = value if isinstance(value, str) else str(value)
    if text.isascii() and text.isprintable():
        return text

    def repl(m: re.Match) -> str:
        ch = m.group(0)
        if keep_newlines and ch in "\n\t":
            return ch
        return _escape(ch) if _unsafe(ch) else ch

    return _FAST.sub(repl, text)


def safe_json_text(text: str) -> str:
    """JSON text with the characters ``json.dumps(ensure_ascii=False)`` leaves raw (DEL, C1,
    bidi and other format characters, U+2028/2029) written as ``\\uXXXX`` escapes; those
    characters only occur inside JSON strings, where the escape means the same character."""
    if text.isascii():
        return text.replace("\x7f", "\\u007f")

    def repl(m: re.Match) -> str:
        ch = m.group(0)
        if ch in "\n\t\r" or not _unsafe(ch):
            return ch
        o = ord(ch)
        if o > 0xFFFF:  # UTF-16 surrogate pair, as JSON spells astral characters
            o -= 0x10000
            return f"\\u{0xD800 + (o >> 10):04x}\\u{0xDC00 + (o & 0x3FF):04x}"
        return f"\\u{o:04x}"

    return _FAST.sub(repl, text)


class SafeStream(io.TextIOBase):
    """A text stream wrapper that escapes terminal-active characters on their way out.

    ``json=True``: for a stream that carries only JSON documents (``--json``), escapes are
    JSON escapes (:func:`safe_json_text`); otherwise :func:`safe` keeping line breaks.
    Everything else (``buffer``, ``fileno``, ``isatty``, ``encoding``) is the wrapped stream's.
    """

    def __init__(self, stream, *, json: bool = False, name: str | None = None):
        self._stream = stream
        self._json = json
        self._name = name  # "standard output": a failed write is an OutputError naming it

    @contextlib.contextmanager
    def _failing(self):
        """A write that fails (no space, a closed stream) as an OutputError naming the stream;
        a broken pipe (``| head``) stays a BrokenPipeError."""
        if self._name is None:
            yield
            return
        if self._stream is None:
            raise OutputError(f"cannot write {self._name}: it is closed")
        try:
            yield
        except BrokenPipeError:
            raise
        except OSError as exc:
            raise OutputError(f"cannot write {self._name}: {exc.strerror or exc}") from None

    def write(self, s: str) -> int:
        with self._failing():
            self._stream.write(safe_json_text(s) if self._json else safe(s, keep_newlines=True))
        return len(s)

    def write_trusted(self, s: str) -> int:
        """Text the station composed with its own escape sequences (a coloured plot), every
        outside string in it already passed through :func:`safe`."""
        with self._failing():
            return self._stream.write(s)

    def writelines(self, lines) -> None:
        for line in lines:
            self.write(line)

    def flush(self) -> None:
        with self._failing():
            if self._stream is not None:
                self._stream.flush()

    def writable(self) -> bool:
        return True

    def isatty(self) -> bool:
        return self._stream.isatty()

    def fileno(self) -> int:
        return self._stream.fileno()

    @property
    def encoding(self):
        return getattr(self._stream, "encoding", "utf-8")

    def __getattr__(self, name):
        return getattr(self._stream, name)


def tui_text(value):
    """A TUI table cell or label for text from outside: escaped, never read as markup."""
    from rich.text import Text

    return Text(safe(value))


ZWSP = "\u200b"  # zero-width space: ends a trailing backslash in markup (tui_markup)


def tui_markup(value) -> str:
    """Text from outside placed inside a Textual markup string: escaped and markup-quoted.

    Every ``[`` is escaped: Textual's ``escape()`` leaves one that looks like no tag
    (``rfc2217://[::1``), and its parser then read the closing tag after it as text.
    A trailing backslash is followed by a zero-width space: Textual takes any ``[`` after a
    backslash for text, so ``C:\\dir\\`` ate the closing tag placed after it; the space
    takes no cell on the screen."""
    text = safe(value).replace("[", "\\[")
    return text + ZWSP if text.endswith("\\") else text
