"""Atomic file and folder writes.

In: bytes, text, JSON-able data, or a function that fills a folder.
Out: files that either appear complete or not at all; an earlier result is never left
half-overwritten, and is replaced only when the caller says so.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from volec.errors import BusyError, OutputExistsError

LOCK_FILE = ".volec.lock"


def _file_mode() -> int:
    """The mode a newly created file gets under the current umask (0666 & ~umask)."""
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def write_bytes_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file in the same folder, then rename."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, _file_mode())  # mkstemp makes 0600 files; give the usual mode
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_text_atomic(path: Path, text: str) -> None:
    """Write UTF-8 ``text`` to ``path`` atomically."""
    write_bytes_atomic(path, text.encode("utf-8"))


def write_json_atomic(path: Path, data: Any) -> None:
    """Write ``data`` as indented JSON (keys in insertion order) atomically."""
    write_text_atomic(path, json.dumps(data, indent=2) + "\n")


def ensure_writable_output(folder: Path, overwrite: bool) -> None:
    """Raise :class:`OutputExistsError` if ``folder`` holds files and ``overwrite`` is False."""
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise OutputExistsError(f"{folder} exists and is a file, not a folder")
    if folder.exists() and any(folder.iterdir()) and not overwrite:
        raise OutputExistsError(
            f"{folder} already exists and is not empty; choose another output folder "
            "or pass overwrite=True (--overwrite) to replace it"
        )


@contextmanager
def atomic_folder(final: Path, overwrite: bool = False) -> Iterator[Path]:
    """Yield a temporary sibling folder to fill; on success it becomes ``final``.

    If ``final`` exists and is not empty, raise :class:`OutputExistsError` unless ``overwrite``;
    with ``overwrite`` the old folder is replaced only after the new one is complete.
    On any exception the temporary folder is removed and ``final`` is left untouched.
    """
    final = Path(final)
    ensure_writable_output(final, overwrite)
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{final.name}.", suffix=".partial", dir=final.parent))
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    old = None
    if final.exists():
        old = final.with_name(f".{final.name}.old-{os.getpid()}")
        os.replace(final, old)
    os.replace(tmp, final)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def fill_folder_atomic(final: Path, fill: Callable[[Path], None], overwrite: bool = False) -> Path:
    """Call ``fill(tmp_folder)`` and publish the folder at ``final`` atomically."""
    with atomic_folder(final, overwrite=overwrite) as tmp:
        fill(tmp)
    return Path(final)


@contextmanager
def folder_lock(folder: Path) -> Iterator[Path]:
    """Hold an exclusive lock on ``folder`` (created if missing) while the block runs: a second
    volec run into the same folder is refused with :class:`BusyError` instead of mixing its
    files with the first one's. The lock is the operating system's (``flock`` on
    ``folder/.volec.lock``), so a run that dies releases it."""
    import fcntl

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / LOCK_FILE
    with open(path, "a+") as f:
        try:
            fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            f.seek(0)
            holder = f.read().strip() or "unknown"
            raise BusyError(f"another volec run ({holder}) is writing into {folder}; wait for it "
                            "to finish, or choose another output folder") from None
        f.seek(0)
        f.truncate()
        f.write(f"pid {os.getpid()}")
        f.flush()
        try:
            yield folder
        finally:
            fcntl.flock(f.fileno(), fcntl.LOCK_UN)
