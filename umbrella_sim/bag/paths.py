# Copyright 2026 umbrella_sim developers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

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
        raise ValueError(f'{what} {path}: {exc.strerror}') from None
    if not stat.S_ISREG(st.st_mode):
        raise ValueError(f'{what} {path}: not a regular file')
    try:
        with open(path, 'rb') as fh:
            data = fh.read()
    except OSError as exc:
        raise ValueError(f'{what} {path}: {exc.strerror}') from None
    if b'\0' in data:
        raise ValueError(f'{what} {path}: binary data (NUL bytes), not a text file')
    try:
        return data.decode('utf-8')
    except UnicodeDecodeError as exc:
        raise ValueError(f'{what} {path}: not UTF-8 text (byte {exc.start})') from None


def absolute_path(path: str, what: str) -> str:
    """
    Return path made absolute, or ValueError naming it when the working directory is gone.

    A relative path is relative to the working directory; when another process deleted that
    directory, ``os.getcwd`` fails (FileNotFoundError, a traceback from ``os.path.abspath``).
    An empty path is refused (it would be the working directory); ``~`` is the home.
    """
    if not path.strip():        # ('' would be the working directory itself)
        raise ValueError(f'{what} {path!r}: empty path')
    path = os.path.expanduser(path)
    if os.path.isabs(path):
        return os.path.normpath(path)
    try:
        return os.path.abspath(path)
    except FileNotFoundError:
        named = what if path in ('', '.') else f'{what} {path}'
        raise ValueError(f'{named}: the working directory no longer exists '
                         '(deleted); give an absolute path or start from an existing '
                         'directory') from None


#: what --overwrite may replace: a regular file, or a recording (a bag directory holding
#: nothing but .mcap files and metadata.yaml); never anything else
OVERWRITABLE = ('file', 'recording')


def check_new_output(path: str, what: str, overwrite: str | None = None,
                     overwrite_option: str | None = '--overwrite') -> str:
    """
    Return the absolute path of an output to be created.

    The absolute path of a file or directory to be created, or ValueError naming why it
    cannot be (it exists: never overwritten unless ``overwrite`` names what it may replace,
    a "file" or a "recording", and it is one; no parent directory; parent not writable).
    Nothing is created or removed (remove_recording does, when the run starts).  A leading
    ``~`` is the home directory, as in a shell (which does not expand it in
    ``-p record_path:=~/bags/run``).  overwrite_option: the caller's option that lets it
    replace one, named in the error (None: it has none, e.g. a node's record_path).
    """
    path = absolute_path(path, what)        # (normalised: no trailing slash)
    if os.path.lexists(path):
        if overwrite is None:
            remedy = (f'{overwrite_option} replaces it' if overwrite_option else
                      'give a new path, or move or remove it')
            raise ValueError(f'{what} {path}: already exists, not overwriting ({remedy})')
        _check_replaceable(path, what, overwrite)
    parent = os.path.dirname(path)
    if not os.path.isdir(parent):
        why = 'is not a directory' if os.path.exists(parent) else 'does not exist'
        raise ValueError(f'{what} {path}: parent directory {parent} {why}')
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ValueError(f'{what} {path}: parent directory {parent} is not writable')
    return path


def _recording_entries(path: str) -> list[str] | None:
    """Return the entries of a recording directory, or None if path is not one."""
    if not os.path.isdir(path) or os.path.islink(path):
        return None
    entries = os.listdir(path)
    ours = [e for e in entries if e == 'metadata.yaml' or e.endswith('.mcap')]
    files = all(os.path.isfile(os.path.join(path, e)) and not
                os.path.islink(os.path.join(path, e)) for e in entries)
    return entries if entries and len(ours) == len(entries) and files else None


def _check_replaceable(path: str, what: str, kind: str) -> None:
    """Raise ValueError unless path is what --overwrite may replace (kind: OVERWRITABLE)."""
    if kind == 'file':
        st = os.lstat(path)
        if not stat.S_ISREG(st.st_mode):
            raise ValueError(f'{what} {path}: exists and is not a regular file, not '
                             'overwriting it even with --overwrite')
    elif kind == 'recording':
        if _recording_entries(path) is None:
            raise ValueError(f'{what} {path}: exists and is not a recording (a directory of '
                             '.mcap files and metadata.yaml only), not removing it even with '
                             '--overwrite')
    else:
        raise ValueError(f"overwrite={kind!r}: one of {', '.join(OVERWRITABLE)}")


def remove_recording(path: str, what: str) -> None:
    """Remove a recording directory that --overwrite replaces (checked again, now)."""
    if not os.path.lexists(path):
        return
    entries = _recording_entries(path)
    if entries is None:
        raise ValueError(f'{what} {path}: no longer a recording, not removing it')
    try:
        for entry in entries:
            os.unlink(os.path.join(path, entry))
        os.rmdir(path)
    except OSError as exc:
        raise ValueError(f'{what} {path}: cannot remove the old recording: '
                         f'{exc.strerror or exc}') from None
