"""A disk that fills up, for the recordings' tests (asnn.io.files.RecordingFile)."""

from __future__ import annotations

import builtins
import errno


class FullDisk:
    """A file that takes the first ``room`` bytes, then none."""

    def __init__(self, file, room: int):
        self._file, self._room = file, room

    def write(self, data):
        if len(data) > self._room:
            raise OSError(errno.ENOSPC, "No space left on device")
        self._room -= len(data)
        return self._file.write(data)

    def __getattr__(self, name):
        return getattr(self._file, name)


def fill_disk_after(monkeypatch, room: int) -> None:
    """Every file asnn.io.files opens from now on (a recording's) takes ``room`` bytes, then
    fails as a full disk does (ENOSPC)."""
    import asnn.io.files as files

    monkeypatch.setattr(files, "open", lambda path, mode="r": FullDisk(
        builtins.open(path, mode), room), raising=False)
