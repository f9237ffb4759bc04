"""
Checks of input and output paths, made before any expensive work.

Every tool reads its text inputs through ``read_text_input`` and checks every output path with
``check_new_output`` first, so a wrong path fails at once, names the file and the reason, and
never overwrites anything.
"""
from __future__ import annotations

import os
import stat


def read_text_input(path: str, what: str) -> str:
    """
    Return the UTF-8 text of a regular file.

    The UTF-8 text of a regular file, or ValueError naming the file and why not (missing,
    a directory or FIFO, unreadable, binary).
    """
    path = os.path.expanduser(path)          # as in a shell (see check_new_output)
    try:
        st = os.stat(path)
    except OSError as exc:
        raise ValueError(f"{what} {path}: {exc.strerror}") from None
    if not stat.S_ISREG(st.st_mode):
        raise ValueError(f"{what} {path}: not a regular file")
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError as exc:
        raise ValueError(f"{what} {path}: {exc.strerror}") from None
    if b"\0" in data:
        raise ValueError(f"{what} {path}: binary data (NUL bytes), not a text file")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{what} {path}: not UTF-8 text (byte {exc.start})") from None


def absolute_path(path: str, what: str) -> str:
    """
    Return path made absolute, or ValueError naming it when the working directory is gone.

    A relative path is relative to the working directory; when another process deleted that
    directory, ``os.getcwd`` fails (FileNotFoundError, a traceback from ``os.path.abspath``).
    An empty path is refused (it would be the working directory); ``~`` is the home.
    """
    if not path.strip():        # ('' would be the working directory itself)
        raise ValueError(f"{what} {path!r}: empty path")
    path = os.path.expanduser(path)
    if os.path.isabs(path):
        return os.path.normpath(path)
    try:
        return os.path.abspath(path)
    except FileNotFoundError:
        named = what if path in ("", ".") else f"{what} {path}"
        raise ValueError(f"{named}: the working directory no longer exists "
                         "(deleted); give an absolute path or start from an existing "
                         "directory") from None


def check_new_output(path: str, what: str) -> str:
    """
    Return the absolute path of an output to be created.

    The absolute path of a file or directory to be created, or ValueError naming why it
    cannot be (it exists: never overwritten; no parent directory; parent not writable).
    Nothing is created.  A leading ``~`` is the home directory, as in a shell (which does
    not expand it in ``-p record_path:=~/bags/run``).
    """
    path = absolute_path(path, what)        # (normalised: no trailing slash)
    if os.path.lexists(path):
        raise ValueError(f"{what} {path}: already exists, not overwriting")
    parent = os.path.dirname(path)
    if not os.path.isdir(parent):
        why = "is not a directory" if os.path.exists(parent) else "does not exist"
        raise ValueError(f"{what} {path}: parent directory {parent} {why}")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ValueError(f"{what} {path}: parent directory {parent} is not writable")
    return path
