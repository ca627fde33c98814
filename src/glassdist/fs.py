"""File-system plumbing shared by every writer of glassdist: atomic writes, locks, leftovers.

A leaf module (it imports nothing of glassdist but its errors):

* :func:`atomic_write` (and ``_bytes``, ``_text``): a temporary name
  (:data:`TEMP_NAME`), then a rename, hashing the bytes as they are written;
* :func:`lock_folder`: an exclusive, non-blocking lock on a folder;
* :func:`pid_alive`, :data:`TEMP_NAME`: what tells a killed writer's temporary file;
* :func:`first_missing`, :func:`remove_empty_tree`, :func:`check_writable`,
  :func:`same_file`, :func:`file_sha256`.
"""

from __future__ import annotations

import hashlib
import os
import re
import secrets
from pathlib import Path

from .errors import InputError

__all__ = [
    "TEMP_NAME", "atomic_write", "atomic_write_bytes", "atomic_write_text", "check_writable", "file_sha256",
    "first_missing", "lock_folder", "pid_alive", "remove_empty_tree", "same_file",
]

# atomic_write's temporary names: .NAME.PID.TOKEN.tmp
TEMP_NAME = re.compile(r"^\.(?P<name>.+)\.(?P<pid>\d+)\.[0-9a-f]{8}\.tmp$")


def file_sha256(path) -> str:
    """SHA-256 (hex) of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def same_file(a: Path, b: Path) -> bool:
    """Whether ``a`` and ``b`` are the same file (False when either is missing)."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def pid_alive(pid: int) -> bool:
    """Whether process ``pid`` may be alive (True unless it provably is not)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError):
        return True  # someone else's live process (or not a pid): not provably ours
    return True


def first_missing(path: Path) -> Path | None:
    """The topmost folder of ``path`` that does not exist yet (None if ``path`` exists)."""
    missing = None
    for p in (path, *path.parents):
        try:
            if p.exists():
                break
        except OSError:  # e.g. a name too long: prepare_output_dir says so
            return None
        missing = p
    return missing


def remove_empty_tree(path: Path, top: Path) -> None:
    """Remove ``path`` and its parents up to ``top`` while they are empty (a refused run leaves no folder)."""
    path, top = Path(path).absolute(), Path(top).absolute()
    if top != path and top not in path.parents:
        return
    for p in (path, *path.parents):
        try:
            p.rmdir()
        except OSError:  # not empty (or gone): keep it and what is above
            return
        if p == top:
            return


def lock_folder(path: Path) -> int | None:
    """Exclusive, non-blocking lock on the folder itself (no lock file left behind)."""
    try:
        import fcntl
    except ImportError:  # no advisory locks on this platform
        return None
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        raise InputError(f"another glassdist run is writing to '{path}'; wait for it to finish or choose another --out") from None
    return fd


def check_writable(path: Path) -> None:
    """Raise InputError unless a file can be created in folder ``path``."""
    probe = path / f".glassdist-probe.{os.getpid()}.{secrets.token_hex(4)}.tmp"
    try:
        os.close(os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
        os.unlink(probe)
    except OSError as exc:
        raise InputError(f"cannot write into output folder '{path}': {exc.strerror}; choose a writable --out") from None


class _HashingFile:
    """A binary file that hashes what is written to it, in order; a seek (a zip header patched) stops the hashing."""

    def __init__(self, fh):
        self._fh, self.sha256, self.sequential, self.size = fh, hashlib.sha256(), True, 0

    def write(self, data):
        n = self._fh.write(data)
        if self.sequential:
            self.sha256.update(memoryview(data)[:n] if n is not None else data)
        self.size += n if n is not None else len(data)
        return n

    def seek(self, *args):
        self.sequential = False
        return self._fh.seek(*args)

    def __getattr__(self, name):  # tell, flush, seekable, ... of the file
        return getattr(self._fh, name)


def atomic_write(path, write, *, digests=None):
    """Write ``path`` by calling ``write(fh)`` on a temporary file in the same folder, then renaming it.

    A reader sees either the previous file or the complete new one, never a part; the
    data is streamed (nothing is held in memory). The file gets the usual permissions
    (``0o666`` less the umask).

    Parameters
    ----------
    path : path
    write : callable
        ``write(fh)`` writes the file's bytes to the binary file ``fh``.
    digests : dict, optional
        Receives ``{path: {"size": bytes, "sha256": hex}}`` of the file written, hashed
        from the bytes as they are written (a writer that seeks back, as ``zipfile``
        does to patch a member's header, has its temporary file hashed before the
        rename instead).

    Returns
    -------
    Path
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    try:
        with os.fdopen(fd, "wb") as fh:
            hashing = _HashingFile(fh)
            write(hashing if digests is not None else fh)
        if digests is not None:
            sha = hashing.sha256.hexdigest() if hashing.sequential else file_sha256(tmp)
            digests[path] = {"size": os.stat(tmp).st_size, "sha256": sha}
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def atomic_write_bytes(path, data, *, digests=None):
    """:func:`atomic_write` of ``data`` (bytes)."""
    return atomic_write(path, lambda fh: fh.write(data), digests=digests)


def atomic_write_text(path, text, *, digests=None):
    """:func:`atomic_write_bytes` for UTF-8 text."""
    return atomic_write_bytes(path, text.encode("utf-8"), digests=digests)
