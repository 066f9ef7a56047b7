"""Reading a file a user names (a parameter file, a robot description, a path): one line when it cannot be.

A missing file, a folder, a file without read permission and a binary file each give a
`TextFileError` whose message names the file and the reason, instead of an OSError or a
UnicodeDecodeError traceback from wherever it was opened.
"""
from __future__ import annotations

import os


class TextFileError(ValueError):
    """The file cannot be read as UTF-8 text (one-line message naming it)."""


def read_text_file(path: str | os.PathLike, what: str = "file") -> str:
    """The file's text, or TextFileError: "cannot read {what} 'PATH': REASON"."""
    try:
        with open(path, encoding="utf-8") as handle:
            return handle.read()
    except OSError as error:
        raise TextFileError(f"cannot read {what} '{os.fspath(path)}': {error.strerror or error}") from None
    except UnicodeDecodeError as error:
        raise TextFileError(f"cannot read {what} '{os.fspath(path)}': not a UTF-8 text file (byte "
                            f"0x{error.object[error.start]:02x} at offset {error.start})") from None
