"""Safe saving: destinations checked before writing, and atomic writes that leave nothing behind.

Every ``save()`` in polar_sim goes through :func:`atomic_write`: the data is written to a
temporary file in the destination's folder and moved over the destination with ``os.replace``,
so a reader (or a crash) sees either the old file or the new one, never a truncated one; on any
error the temporary file is removed. :func:`check_destination` refuses what a save must never
replace or touch: an integer "path" (a file descriptor), a directory, a device, a FIFO, a socket.
"""

from __future__ import annotations

import contextlib
import os
import stat
import tempfile
from pathlib import Path

__all__ = ["check_destination", "check_source", "atomic_write"]


def _show(p) -> str:
    """A path for an error message: at most 200 characters (paths can be 4,096 bytes long)."""
    s = str(p)
    return repr(s) if len(s) <= 200 else repr(s[:120] + "..." + s[-60:])


def check_destination(path, name: str = "path") -> Path:
    """``path`` as a :class:`~pathlib.Path` that a save may create or replace.

    Raises ``TypeError`` for anything but a ``str``/``os.PathLike`` (an ``int`` would be taken as
    a file descriptor), and ``ValueError`` for an empty path, a path with a NUL byte, or an
    existing destination that is not a regular file (directory, device, FIFO, socket).
    """
    if isinstance(path, (bool, int)) or not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"{name}: expected a str or os.PathLike file path, got {type(path).__name__}")
    try:
        p = Path(os.fspath(path)).expanduser()
    except (TypeError, RuntimeError) as exc:      # bytes paths; "~user" with no such user
        raise ValueError(f"{name}: {path!r} is not a usable file path ({exc})") from None
    if not str(p) or str(p) == "." or "\x00" in str(p):
        raise ValueError(f"{name}: {_show(path)} is not a file path")
    try:
        st = p.stat()
    except FileNotFoundError:
        return p
    except OSError as exc:
        raise ValueError(f"{name}: cannot use {_show(p)}: {exc.strerror}") from None
    if not stat.S_ISREG(st.st_mode):
        kind = "a directory" if stat.S_ISDIR(st.st_mode) else "not a regular file"
        raise ValueError(f"{name}: {_show(p)} is {kind}; a save replaces only regular files")
    return p


def check_source(path, name: str = "path") -> Path:
    """``path`` as a :class:`~pathlib.Path` of an existing regular file to read.

    ``TypeError`` for a non-path (an ``int`` included), ``FileNotFoundError`` for a missing file,
    ``ValueError`` for something that is not a regular file.
    """
    if isinstance(path, (bool, int)) or not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"{name}: expected a str or os.PathLike file path, got {type(path).__name__}")
    try:
        p = Path(os.fspath(path)).expanduser()
    except (TypeError, RuntimeError) as exc:
        raise ValueError(f"{name}: {path!r} is not a usable file path ({exc})") from None
    if "\x00" in str(p):
        raise ValueError(f"{name}: {_show(path)} is not a file path")
    try:
        st = p.stat()
    except FileNotFoundError:
        raise FileNotFoundError(f"{name}: {_show(p)} does not exist") from None
    except OSError as exc:
        raise ValueError(f"{name}: cannot read {_show(p)}: {exc.strerror}") from None
    if not stat.S_ISREG(st.st_mode):
        raise ValueError(f"{name}: {_show(p)} is not a regular file")
    return p


@contextlib.contextmanager
def atomic_write(path, name: str = "path", mode: str = "wb"):
    """Context manager yielding a file object; on success the file replaces ``path`` atomically.

    >>> with atomic_write("map.npz") as fh:
    ...     np.savez_compressed(fh, **arrays)
    """
    p = check_destination(path, name)
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ValueError(f"{name}: cannot create the folder of {_show(p)}: {exc.strerror}") from None
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{p.name[:80]}.", suffix=".tmp", dir=p.parent)
    except OSError as exc:
        raise ValueError(f"{name}: cannot write in {_show(p.parent)}: {exc.strerror}") from None
    try:
        with os.fdopen(fd, mode) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        check_destination(p, name)      # the destination may have changed meanwhile
        os.replace(tmp, p)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
