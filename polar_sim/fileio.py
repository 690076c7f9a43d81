"""Safe saving: destinations checked before writing, and atomic writes that leave nothing behind.

Every save in polar_sim goes through :func:`atomic_write` (or :func:`write_text`): the data is
written to a temporary file in the destination's folder and moved over the destination with
``os.replace``, so a reader (or a crash) sees either the old file or the new one, never a
truncated one. The new file gets the mode the user's umask gives (``0o666 & ~umask``, 0644
typically), as a file written with ``open()`` would. On an error the temporary file is removed.

A save killed outright (SIGKILL, a power cut) cannot remove its temporary file, so the next
successful save of the same destination does: it removes the temporary files of that destination
(the name pattern ``.<name>.<16 hex digits>.tmp``; see :func:`temp_name`) whose writer is gone.
A writer holds an exclusive ``flock`` on its temporary file until it is renamed, and the kernel
drops that lock when the writer dies, however it dies; a file whose lock is still held belongs
to a save in flight (in this or another process) and is left alone.

:func:`check_destination` refuses what a save must never replace or touch: an integer "path" (a
file descriptor), a directory, a device, a FIFO, a socket.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
import secrets
import stat
from pathlib import Path

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX: no locks, and no clean-up of orphans
    fcntl = None

__all__ = ["check_destination", "check_source", "atomic_write", "write_text", "temp_name", "remove_orphans"]

#: An old polar_sim's ``tempfile.mkstemp`` names (8 characters) are matched too, so the orphans
#: of earlier versions are cleaned up as well.
_TOKEN = r"(?:[0-9a-f]{16}|[a-z0-9_]{8})"


def _show(p) -> str:
    """A path for an error message: at most 200 characters (paths can be 4,096 bytes long)."""
    s = str(p)
    return repr(s) if len(s) <= 200 else repr(s[:120] + "..." + s[-60:])


def _as_path(path, name):
    if isinstance(path, (bool, int)) or not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"{name}: expected a str or os.PathLike file path, got {type(path).__name__}")
    try:
        return Path(os.fspath(path)).expanduser()
    except (TypeError, RuntimeError) as exc:      # bytes paths; "~user" with no such user
        raise ValueError(f"{name}: {path!r} is not a usable file path ({exc})") from None


def check_destination(path, name: str = "path") -> Path:
    """``path`` as a :class:`~pathlib.Path` that a save may create or replace.

    Raises ``TypeError`` for anything but a ``str``/``os.PathLike`` (an ``int`` would be taken as
    a file descriptor), and ``ValueError`` for an empty path, a path with a NUL byte, or an
    existing destination that is not a regular file (directory, device, FIFO, socket).
    """
    p = _as_path(path, name)
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
    p = _as_path(path, name)
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


def _stem(filename: str) -> str:
    """The part of a temporary file's name that names its destination: the file name, or for a
    name too long to take a suffix (a name holds at most 255 bytes), its start and a digest."""
    if len(filename.encode()) <= 200:
        return filename
    digest = hashlib.sha256(filename.encode()).hexdigest()[:16]
    return filename.encode()[:120].decode(errors="ignore") + "~" + digest


def temp_name(path, token: str | None = None) -> Path:
    """The temporary file a save of ``path`` writes first: ``.<name>.<token>.tmp`` in its folder,
    ``token`` 16 random hex digits. The token has no dot, so the pattern of one destination
    (``a``) never matches another's (``a.b``)."""
    p = Path(path)
    return p.with_name(f".{_stem(p.name)}.{token or secrets.token_hex(8)}.tmp")


def _temp_pattern(path):
    return re.compile(rf"\.{re.escape(_stem(Path(path).name))}\.{_TOKEN}\.tmp")


def remove_orphans(path) -> list:
    """Remove the temporary files of saves of ``path`` whose writer is gone; return their paths.

    A candidate is a regular file in ``path``'s folder whose name matches :func:`temp_name`'s
    pattern for ``path``. It is removed only if an exclusive non-blocking ``flock`` on it can be
    taken (no live writer holds it) and the name still refers to the file that was locked;
    anything else (a save in flight, a file that cannot be opened) is left alone.
    """
    p = Path(path)
    if fcntl is None:  # pragma: no cover
        return []
    pattern, removed = _temp_pattern(p), []
    try:
        entries = list(os.scandir(p.parent))
    except OSError:
        return removed
    for e in entries:
        if not pattern.fullmatch(e.name):
            continue
        try:
            fd = os.open(e.path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
        except OSError:
            continue
        try:
            st = os.fstat(fd)
            if not stat.S_ISREG(st.st_mode):
                continue
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)   # OSError: a live writer holds it
            if os.stat(e.path, follow_symlinks=False).st_ino == st.st_ino:
                os.unlink(e.path)
                removed.append(Path(e.path))
        except OSError:
            pass
        finally:
            os.close(fd)
    return removed


def _open_locked_temp(p: Path, name: str):
    """Create and lock a new temporary file for ``p``: ``(fd, temp path)``. Mode 0o666 filtered
    by the umask, as ``open()`` gives. A clean-up may have removed the file between its creation
    and the lock (it was not locked yet); then another name is tried."""
    for _ in range(100):
        tmp = temp_name(p)
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0), 0o666)
        except FileExistsError:
            continue
        except OSError as exc:
            raise ValueError(f"{name}: cannot write in {_show(p.parent)}: {exc.strerror}") from None
        if fcntl is None:  # pragma: no cover
            return fd, tmp
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            if os.stat(tmp).st_ino == os.fstat(fd).st_ino:
                return fd, tmp
        except OSError:
            pass
        os.close(fd)
    raise ValueError(f"{name}: cannot create a temporary file in {_show(p.parent)}")  # pragma: no cover


@contextlib.contextmanager
def atomic_write(path, name: str = "path", mode: str = "wb", *, encoding: str | None = None, newline: str | None = None):
    """Context manager yielding a file object; on success the file replaces ``path`` atomically.

    ``mode``: ``"wb"`` or ``"w"`` (text, ``encoding`` default UTF-8). The file gets the mode the
    umask gives (0644 typically); the destination's folder is created if missing. Errors about
    the destination raise ``ValueError`` naming ``name``; on any error the destination is left as
    it was and the temporary file is removed. After a successful save, the temporary files that
    killed saves of the same destination left behind are removed (:func:`remove_orphans`).

    >>> with atomic_write("map.npz") as fh:
    ...     np.savez_compressed(fh, **arrays)
    """
    if mode not in ("wb", "w"):
        raise ValueError(f"mode: expected 'wb' or 'w', got {mode!r}")
    p = check_destination(path, name)
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ValueError(f"{name}: cannot create the folder of {_show(p)}: {exc.strerror}") from None
    fd, tmp = _open_locked_temp(p, name)
    try:
        text = {} if mode == "wb" else {"encoding": encoding or "utf-8", "newline": newline}
        with os.fdopen(fd, mode, **text) as fh:   # closing it releases the lock, after the rename
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
            check_destination(p, name)      # the destination may have changed meanwhile
            os.replace(tmp, p)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    remove_orphans(p)


def write_text(path, text: str, name: str = "path") -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically through :func:`atomic_write`; returns the path."""
    with atomic_write(path, name, "w") as fh:
        fh.write(text)
    return Path(path)
