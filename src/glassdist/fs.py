"""File-system plumbing shared by every writer of glassdist: atomic writes, locks, leftovers.

A leaf module (it imports nothing of glassdist but its errors):

* :func:`atomic_write` (and ``_bytes``, ``_text``): a temporary name
  (:data:`TEMP_NAME`), then a rename, hashing the bytes as they are written;
* :func:`lock_folder`: an exclusive, non-blocking lock on a folder;
* :func:`pid_alive`, :data:`TEMP_NAME`: what tells a killed writer's temporary file;
* :func:`first_missing`, :func:`remove_empty_tree`, :func:`check_writable`,
  :func:`same_file`, :func:`file_sha256`;
* :func:`csv_cell`, :func:`csv_text`, :func:`write_csv`: CSV exports whose text cells a
  spreadsheet cannot run as formulas (the batch index, the sweep index, the history export).
"""

from __future__ import annotations

import hashlib
import os
import re
import secrets
from pathlib import Path

from .errors import InputError

__all__ = [
    "PATCH_WINDOW_BYTES", "TEMP_NAME", "atomic_write", "atomic_write_bytes", "atomic_write_text", "check_writable", "file_sha256",
    "first_missing", "lock_folder", "pid_alive", "remove_empty_tree", "same_file", "csv_cell", "csv_text", "write_csv",
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


#: most bytes held back from the hash while a writer may still patch them (one zip member's data)
PATCH_WINDOW_BYTES = 64 << 20


class _HashingFile:
    """A binary file that hashes its bytes as they are written, in order.

    ``zipfile`` (``numpy.savez``, :func:`glassdist.storage.fields.write_npz`) writes a
    member's header, its data, then seeks back to patch the header with the sizes and
    CRC, and returns to the end. The bytes since the last return to the end are held
    (at most :data:`PATCH_WINDOW_BYTES`: one member) until the writer is back at the end
    with no patch pending; only then are they hashed. A writer that seeks further back,
    or a member larger than the window, leaves ``hashed`` False (the caller then hashes
    the finished temporary file instead).
    """

    def __init__(self, fh):
        self._fh, self.sha256, self.hashed = fh, hashlib.sha256(), True
        self._held, self._held_at, self._end = bytearray(), 0, 0  # bytes not hashed yet, their offset, file size

    def write(self, data):
        view = memoryview(data).cast("B")
        at = self._fh.tell()
        n = self._fh.write(view)
        n = len(view) if n is None else n
        if self.hashed:
            if at < self._held_at:
                self.hashed = False
            else:
                i = at - self._held_at
                self._held[i:i + n] = view[:n]
                if len(self._held) > PATCH_WINDOW_BYTES:
                    self.hashed = False
                    self._held = bytearray()
        self._end = max(self._end, at + n)
        return n

    def seek(self, offset, whence=0):
        pos = self._fh.seek(offset, whence)
        if self.hashed:
            if pos < self._held_at:
                self.hashed = False
                self._held = bytearray()
            elif pos == self._end:  # back at the end: what is held is final
                self._settle()
        return pos

    def _settle(self):
        self.sha256.update(self._held)
        self._held_at += len(self._held)
        self._held = bytearray()

    def hexdigest(self) -> str | None:
        """SHA-256 of everything written (None when the writer's seeks could not be followed)."""
        if not self.hashed:
            return None
        self._settle()
        return self.sha256.hexdigest()

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
        from the bytes as they are written, the patches of a ``zipfile`` writer followed
        (:class:`_HashingFile`); only a writer whose seeks cannot be followed (a zip
        member over :data:`PATCH_WINDOW_BYTES`) has its temporary file read to hash it.

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
            sha = hashing.hexdigest() or file_sha256(tmp)
            digests[path] = {"size": os.stat(tmp).st_size, "sha256": sha}
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def atomic_write_bytes(path, data, *, digests=None):
    """:func:`atomic_write` of ``data`` (bytes; ``digests`` as there, hashed from ``data``)."""
    path = atomic_write(path, lambda fh: fh.write(data))
    if digests is not None:
        view = memoryview(data).cast("B")
        digests[path] = {"size": len(view), "sha256": hashlib.sha256(view).hexdigest()}
    return path


def atomic_write_text(path, text, *, digests=None):
    """:func:`atomic_write_bytes` for UTF-8 text."""
    return atomic_write_bytes(path, text.encode("utf-8"), digests=digests)


_FORMULA_START = ("=", "+", "-", "@", "\t", "\r")


def csv_cell(value):
    """A text cell that a spreadsheet would run as a formula (``=``, ``+``, ``-``, ``@``, tab, CR) gets a ``'``."""
    if isinstance(value, str) and value.startswith(_FORMULA_START):
        try:
            float(value)
        except ValueError:
            return "'" + value
    return value


def csv_text(rows, columns=None) -> str:
    """CSV text of ``rows`` (dicts; header ``columns``, default the first row's keys); formula-like cells defused."""
    import csv
    import io

    rows = list(rows)
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(columns if columns is not None else rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows({k: csv_cell(v) for k, v in row.items()} for row in rows)
    return buf.getvalue()


def write_csv(path, rows):
    """Write rows (dicts with the same keys) as a CSV file, atomically (:func:`csv_text`); the path."""
    return atomic_write_text(path, csv_text(rows))
