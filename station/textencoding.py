"""A text file's encoding, decided once for the capture reader and the CSV importer: UTF-8,
else Windows-1252 (what Excel's "CSV (Comma delimited)" saves on Windows) or UTF-16 with a
byte-order mark (Excel's "Unicode Text"); anything else refused in one line."""

from __future__ import annotations

import codecs
from collections.abc import Iterator

from station.errors import InputError
from station.fileio import looks_utf16, open_input

MAX_LINE_BYTES = 1 << 20  # a line longer than this is no CSV row (the capture reader's limit)
_CHUNK_BYTES = 1 << 20
# what str.splitlines ends a line at ("\r\n" is one end)
LINE_ENDS = "\n\r\v\f\x1c\x1d\x1e\x85\u2028\u2029"


UTF16_BOMS = (codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)
# what Excel's "CSV (Comma delimited)" saves in on Windows: read where a file is not UTF-8
CP1252 = "cp1252"


def bom_encoding(path) -> str:
    """``"utf-16"`` for a file that starts with a UTF-16 byte-order mark (LE or BE: Excel's
    "Unicode Text"), else ``"utf-8"``."""
    try:
        with open_input(path, "a CSV file") as f:
            head = f.read(2)
    except (InputError, OSError):  # the reader that follows says why
        return "utf-8"
    return "utf-16" if head.startswith(UTF16_BOMS) else "utf-8"


def read_chunks(f, path, utf16: bool = False) -> Iterator[bytes]:
    """The file in chunks, each checked as it comes: a NUL byte or a line longer than
    ``MAX_LINE_BYTES`` stops the reading at once (``/dev/zero``, a binary blob or a file
    without line ends would otherwise be read on and on). ``utf16``: a file with a UTF-16
    byte-order mark, whose NUL bytes are half its characters (a NUL character is refused
    once decoded, by :func:`check_text`)."""
    lines_before = 0  # newlines in the chunks already read
    run = 0  # bytes since the last newline
    first_chunk = True
    too_long = f"line longer than {MAX_LINE_BYTES} bytes: not a CSV row"
    while True:
        chunk = f.read(_CHUNK_BYTES)  # no longer than the limit: a longer line crosses a chunk's end
        if not chunk:
            return
        nul = -1 if utf16 else chunk.find(b"\0")
        if nul >= 0 and first_chunk and looks_utf16(chunk):
            raise InputError(
                path, 1, "UTF-16 text without a byte-order mark; save the file as UTF-8 (or as Unicode Text, with one)"
            )
        if nul >= 0:
            raise InputError(
                path, lines_before + chunk.count(b"\n", 0, nul) + 1, "NUL byte: binary data, not a CSV file"
            )
        first = chunk.find(b"\n")
        if first < 0:
            run += len(chunk)
        elif run + first > MAX_LINE_BYTES:
            raise InputError(path, lines_before + 1, too_long)
        else:
            run = len(chunk) - chunk.rfind(b"\n") - 1
        lines_before += chunk.count(b"\n")
        if run > MAX_LINE_BYTES:
            raise InputError(path, lines_before + 1, too_long)
        first_chunk = False
        yield chunk


def _check_utf16(path) -> None:
    """:func:`check_text` for a file with a UTF-16 byte-order mark: every character decodes
    and none is NUL (binary data behind a mark)."""
    decoder = codecs.getincrementaldecoder("utf-16")()
    lines_before = 0
    try:
        with open_input(path, "a CSV file") as f:
            for chunk in read_chunks(f, path, utf16=True):
                try:
                    text = decoder.decode(chunk)
                except UnicodeDecodeError as exc:
                    raise InputError(path, lines_before + 1, f"not UTF-16 text: {exc.reason}") from None
                nul = text.find("\0")
                if nul >= 0:
                    raise InputError(
                        path, lines_before + text.count("\n", 0, nul) + 1, "NUL character: binary data, not a CSV file"
                    )
                lines_before += text.count("\n")
            decoder.decode(b"", final=True)
    except UnicodeDecodeError as exc:  # a character cut off by the end of the file
        raise InputError(path, lines_before + 1, f"not UTF-16 text: {exc.reason}") from None
    except OSError as exc:  # reading, after the open
        raise InputError(path, None, f"cannot read: {exc.strerror or exc}") from None


def check_text(path) -> tuple[str, str | None]:
    """Read the file once, keeping nothing: the encoding to read it in and the warning that
    says so, or InputError for what is not text (a NUL byte, an overlong line, then the first
    byte that is not UTF-8, naming its line).

    UTF-16 with a byte-order mark (Excel's "Unicode Text") is read as such. A file that is not
    UTF-8 is read as Windows-1252 (Excel's "CSV (Comma delimited)" on Windows: '°' is 0xb0,
    'µ' 0xb5) when every byte is a Windows-1252 character, said in the warning; a byte that is
    none (0x81, 0x8d, 0x8f, 0x90, 0x9d) leaves it refused as not UTF-8."""
    if bom_encoding(path) == "utf-16":
        _check_utf16(path)
        return "utf-16", None
    decoder = codecs.getincrementaldecoder("utf-8")()
    bad = None  # the first UTF-8 error: reported once no NUL or overlong line follows it
    cp1252 = True  # every byte so far is a Windows-1252 character
    bom = None  # a UTF-8 byte-order mark: written as UTF-8, never read as Windows-1252
    lines_before = 0
    try:
        with open_input(path, "a CSV file") as f:
            for chunk in read_chunks(f, path):
                if bom is None:
                    bom = chunk.startswith(codecs.BOM_UTF8)
                if bad is None:
                    try:
                        decoder.decode(chunk)
                    except UnicodeDecodeError as exc:  # exc.object: the bytes held over, then this chunk
                        bad = (lines_before + exc.object[: exc.start].count(b"\n") + 1, exc.object[exc.start])
                if cp1252:
                    try:
                        chunk.decode(CP1252)  # one byte a character: chunks decode alone
                    except UnicodeDecodeError:
                        cp1252 = False
                lines_before += chunk.count(b"\n")
    except OSError as exc:  # reading, after the open
        raise InputError(path, None, f"cannot read: {exc.strerror or exc}") from None
    if bad is None:
        try:
            decoder.decode(b"", final=True)
        except UnicodeDecodeError as exc:  # a character cut off by the end of the file
            bad = (lines_before + exc.object[: exc.start].count(b"\n") + 1, exc.object[exc.start])
    if bad is None:
        return "utf-8", None
    if not cp1252 or bom:
        why = "under a UTF-8 byte-order mark" if bom else "nor a Windows-1252 character"
        raise InputError(path, bad[0], f"not UTF-8 text: byte 0x{bad[1]:02x} ({why}): save the file as UTF-8")
    return CP1252, (
        f"not UTF-8 (byte 0x{bad[1]:02x} on line {bad[0]}): read as Windows-1252, as Excel's "
        "'CSV (Comma delimited)' saves on Windows"
    )


def text_encoding(path, what: str = "a CSV file") -> tuple[str, str | None]:
    """The encoding a text file is read in (``utf-8``, ``cp1252``, ``utf-16``) and the warning
    that says so, or InputError for what is none (:func:`check_text`): the one decision the
    importer and the capture reader (``station.capture.read_capture``) share. ``what``: the
    file's kind in a refusal ("not a CSV file" is said of a capture as "not a capture file")."""
    try:
        return check_text(path)
    except InputError as exc:
        if what != "a CSV file":  # 'not a CSV file', 'not a CSV row' said of what it is
            row = what.replace("file", "row")
            message = exc.message.replace("a CSV file", what).replace("a CSV row", row)
            raise InputError(exc.path, exc.line, message) from None
        raise


def copy_as_utf8(path, encoding: str, dest) -> None:
    """Write the text of ``path`` (in ``encoding``, as :func:`text_encoding` found it) to
    ``dest`` as UTF-8, byte for byte the same lines and line ends (a UTF-16 byte-order mark is
    no text). ``dest`` is a new file of the caller's (a temporary one): an OSError writing it is
    the caller's to say; reading ``path`` is an InputError."""
    with open(dest, "wb") as out:
        for text in _decoded(path, encoding):
            out.write(text.encode("utf-8", "surrogatepass"))


def _decoded(path, encoding: str) -> Iterator[str]:
    """The text of ``path`` in ``encoding``, a chunk at a time."""
    decoder = codecs.getincrementaldecoder(encoding)()
    try:
        with open_input(path, "a CSV file") as f:
            for chunk in read_chunks(f, path, utf16=encoding == "utf-16"):
                yield decoder.decode(chunk)
            yield decoder.decode(b"", final=True)
    except UnicodeDecodeError:
        raise InputError(path, None, f"changed while it was read: not {encoding} text any more") from None
    except OSError as exc:
        raise InputError(path, None, f"cannot read: {exc.strerror or exc}") from None
