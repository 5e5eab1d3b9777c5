"""Files written whole: a process killed while it writes leaves the old file or the new one,
and processes that read, change and write one file take turns; and recordings, written to a new
file that keeps its first failed write (:class:`RecordingFile`)."""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

__all__ = ["LOOP_OF_LINKS", "RecordingFile", "folder_lock", "folder_problem", "link_loops",
           "make_folders", "output_problem", "path_problem", "remove_folders", "resolved",
           "seekable_target", "write_atomically"]


def resolved(path: str | Path) -> Path:
    """``Path(path).resolve()``, or for a link that loops (RuntimeError up to Python 3.12,
    OSError from 3.13) the path made absolute: such a file is then named by what opens it, not
    a traceback."""
    try:
        return Path(path).resolve()
    except (OSError, RuntimeError):
        return Path(path).absolute()


def seekable_target(path: str | Path) -> None:
    """Refuse to write a video or a bag to a path that exists and is not a regular file: their
    writers seek back, and OpenCV's waited without a word for a pipe's reader (ValueError)."""
    path = Path(path)
    if path.exists() and not path.is_file():
        raise ValueError(f"{path}: not a regular file (a pipe, a device or a folder): a video "
                         "or a bag is written with seeks")


LOOP_OF_LINKS = "leads back to itself (a loop of links)"
"""What a link is said to do whose links loop (ELOOP), wherever a path is refused for it."""


def link_loops(path: str | Path) -> bool:
    """Whether following ``path``'s links loops (ELOOP)."""
    try:
        os.stat(path)
    except OSError as exc:
        return exc.errno == errno.ELOOP
    return False


def path_problem(path: str | Path) -> str | None:
    """Why ``path`` cannot even be looked up (a name longer than the file system takes, a loop
    of links, a folder on the way this process may not search), or None where it is there or
    merely missing: ``Path.exists`` and ``Path.is_dir`` raise for those, and a check of an
    output made with them ended in a traceback."""
    try:
        os.stat(path)
    except (FileNotFoundError, NotADirectoryError):
        return None
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            return f"a link that {LOOP_OF_LINKS}"
        return exc.strerror or str(exc)
    return None


def folder_problem(folder: str | Path) -> str | None:
    """Why ``folder`` cannot be had for writing into, found before a run, or None: the nearest
    folder there is on the way to it is a folder this process may write, and a file can be
    made in ``folder`` (:func:`_write_problem`; the outputs' folders are made as they are
    written)."""
    folder = Path(folder)
    problem = path_problem(folder)
    if problem:
        return f"{folder}: {problem}"
    parent = folder
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        return f"{parent} is not a folder"
    if parent != folder and not os.access(parent, os.W_OK | os.X_OK):
        return f"cannot make {folder} in {parent} (no write access)"
    return _write_problem(folder)


def output_problem(path: str | Path) -> str | None:
    """Why a file written in place at ``path`` cannot be had, found before a run, or None: its
    name cannot be looked up (:func:`path_problem`), or, for a new file, its folder cannot be
    had for writing into (:func:`folder_problem`). An existing file is opened where it is, so
    its folder need take no new file: ``/dev/null``, ``/proc/self/fd/1``, a file of one's own
    in a folder one may not write (trying the folder refused them all)."""
    problem = path_problem(path)
    if problem or os.path.exists(path):
        return problem
    return folder_problem(Path(path).parent)


def _write_problem(folder: Path) -> str | None:
    """Why no file can be made in ``folder``, found by making one (and the folders missing on
    the way), all removed again; or None. Permissions do not say it: root may write anywhere by
    them, and /proc or /sys refuse what they allow (``--out /proc/foo`` failed at the end of
    the run, with a bare errno)."""
    try:
        made = make_folders(folder)
    except OSError as exc:
        return f"cannot make {exc.filename}: {exc.strerror or exc}"
    try:
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".asnn-"):
            pass
    except OSError as exc:
        return f"cannot write in {folder}: {exc.strerror or exc}"
    finally:
        remove_folders(made)
    return None


def make_folders(folder: Path) -> list[Path]:
    """Make ``folder`` and the folders missing on the way to it; those this call made, deepest
    first (what :func:`remove_folders` takes). Only a folder ``os.mkdir`` itself created is
    counted: not one there already under another spelling (``a/../b`` where ``b`` exists), nor
    one another process made meanwhile.

    Raises
    ------
    OSError
        A folder that cannot be made; those made before it are removed.
    """
    missing = []
    for step in (folder, *folder.parents):  # deepest first, up to the first that is there
        if step.is_dir():
            break
        missing.append(step)
    made: list[Path] = []
    try:
        for step in reversed(missing):
            try:
                os.mkdir(step)
            except FileExistsError:
                if not step.is_dir():  # a file, or a link to none, where a folder goes
                    raise
                continue
            made.insert(0, step)
    except OSError:
        remove_folders(made)
        raise
    return made


def remove_folders(folders: list[Path]) -> None:
    """Remove the folders :func:`make_folders` made, deepest first (each only if empty: what
    another process put there meanwhile stays)."""
    for folder in folders:
        with contextlib.suppress(OSError):
            folder.rmdir()


def write_atomically(path: str | Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` through a temporary file beside it, flushed to disk
    and renamed over it. Where ``path`` is a symbolic link, its target is replaced and the
    link kept. The file keeps its permission bits (a new one gets the umask's).

    Raises
    ------
    OSError
        If the folder cannot take the temporary file or the rename fails; ``path`` is then
        as it was.
    """
    target = Path(os.path.realpath(path))
    mode = target.stat().st_mode & 0o7777 if target.exists() else None
    fd, temporary = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.",
                                     suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        if mode is None:
            umask = os.umask(0)
            os.umask(umask)
            mode = 0o666 & ~umask
        os.chmod(temporary, mode)
        os.replace(temporary, target)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(temporary)
        raise


@contextlib.contextmanager
def folder_lock(path: str | Path) -> Iterator[None]:
    """Hold an exclusive lock on the folder of ``path`` (a link's target's folder): other
    processes taking it for the same folder wait. For a read, change and write of one file
    that :func:`write_atomically` replaces (a lock on the file itself would be on the inode
    the rename retires)."""
    folder = os.path.dirname(os.path.realpath(path))
    fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # releases the lock


class RecordingFile:
    """A recording's file as its MCAP writer writes it, keeping the first error: a writer may
    report none to its caller (the Foxglove SDK's logs it; a writer on a thread of its own has
    no caller to raise to), so its user checks :attr:`error` and stops at the first write that
    failed (a full disk).

    The file is new: a recording never overwrites one (unless ``overwrite``).

    Raises
    ------
    OSError
        One line naming the file: it exists (without ``overwrite``), or cannot be created (a
        folder that is missing or not writable).
    """

    def __init__(self, path: str | Path, *, overwrite: bool = False):
        self.path = Path(path)
        try:
            self._file = open(self.path, "wb" if overwrite else "xb")  # noqa: SIM115
        except FileExistsError:
            raise OSError(f"{self.path}: exists; a recording goes to a new file") from None
        except OSError as exc:
            raise OSError(f"cannot write {self.path}: {exc.strerror or exc}") from None
        self.error: OSError | None = None

    def _kept(self, call, *args):
        try:
            return call(*args)
        except OSError as exc:
            self.error = self.error or exc
            raise

    def write(self, data) -> int:
        return self._kept(self._file.write, data)

    def seek(self, offset: int, whence: int = 0) -> int:
        return self._kept(self._file.seek, offset, whence)

    def tell(self) -> int:
        return self._file.tell()

    def flush(self) -> None:
        self._kept(self._file.flush)

    def close(self) -> None:
        try:
            self._kept(self._file.close)  # flushes what is buffered
        except OSError:
            pass  # kept in error
