"""Crash-safe file-system primitives for the model store and bundle writer.

Every mutation the bundle/model-store code makes to disk goes through one of these functions.
That keeps the durability rules (fsync file data, then fsync the directory that names it) in one
place, and gives the tests a single seam where a power cut can be simulated at any step.
Callers use ``from edge import durable`` and call ``durable.<fn>`` so the seam can be patched.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path


def write_new_file(path: Path, data: bytes) -> None:
    """Create ``path`` (must not exist), write ``data``, fsync it.

    Raises
    ------
    FileExistsError
        If ``path`` already exists (``O_EXCL`` also refuses to follow a planted symlink).
    """
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0), 0o644)
    try:
        view = memoryview(data)
        while view:
            n = os.write(fd, view)
            view = view[n:]
        os.fsync(fd)
    finally:
        os.close(fd)


def fsync_dir(path: Path) -> None:
    """Flush a directory's entries (names created, renamed or removed in it) to disk."""
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def make_dir(path: Path) -> None:
    """Create one directory (parent must exist; refuses an existing path)."""
    os.mkdir(path, 0o755)


def replace(src: Path, dst: Path) -> None:
    """Atomically rename ``src`` over ``dst`` (``os.replace``; same file system)."""
    os.replace(src, dst)


def rename_dir(src: Path, dst: Path) -> None:
    """Atomically rename directory ``src`` to a not-yet-existing ``dst``."""
    if os.path.lexists(dst):
        raise FileExistsError(f"{dst} already exists")
    os.rename(src, dst)


def remove_tree(path: Path) -> None:
    """Delete a directory tree or a single file/symlink; a missing path is not an error."""
    p = Path(path)
    if p.is_symlink() or p.is_file():
        p.unlink(missing_ok=True)
    elif p.exists():
        shutil.rmtree(p)


def atomic_write_file(path: Path, data: bytes) -> None:
    """Replace ``path`` with ``data`` so that a crash leaves either the old or the new content.

    Writes a sibling temp file, fsyncs it, ``os.replace``-s it over ``path`` and fsyncs the
    directory.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    remove_tree(tmp)
    write_new_file(tmp, data)
    replace(tmp, path)
    fsync_dir(path.parent)


def free_bytes(path: Path) -> int:
    """Bytes available to this process on the file system holding ``path`` (a seam for tests)."""
    return shutil.disk_usage(path).free


def remove_stray_temporaries(path: Path) -> list[Path]:
    """Delete the temp siblings :func:`atomic_write_file` leaves when a crash hits it mid-write.

    Returns the paths removed. The temporaries are named ``.<name>.tmp<pid>``.
    """
    path = Path(path)
    removed = []
    if not path.parent.is_dir():
        return removed
    prefix = f".{path.name}.tmp"
    for entry in os.listdir(path.parent):
        if entry.startswith(prefix):
            remove_tree(path.parent / entry)
            removed.append(path.parent / entry)
    return removed
