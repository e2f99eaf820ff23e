"""Checks every reader makes before it reads a user's file, so that no input can block a read, pull in another file
or make a reader allocate memory the file does not hold.

* ``regular_file``: the path must name a regular file. A FIFO, socket or device would block ``open`` or never end
  (``/dev/zero``); a directory cannot be read. Each is refused in one line that says what the path is.
* ``read_head``: the first bytes of a regular file for the content sniffers, or ``None`` (never raises, never blocks).
* ``open_hdf5``: a regular file with the HDF5 signature, opened read-only, whose storage ``check_hdf5_storage``
  accepts. Every HDF5 reader of ``data_formats`` opens files through it.
* ``check_hdf5_storage``: every link and dataset of the file, before any data is read. Refused: external links
  (another file's objects), external storage (a dataset whose bytes live in another file, which could be any local
  file or a FIFO), virtual datasets (mapped from other files), a dataset that declares more than
  ``max_dataset_bytes()`` (environment variable ``KNIT_MAX_DATASET_BYTES``, default 8 GiB), and a dataset larger than
  ``MIN_CHECKED_BYTES`` that stores less than 1/``MAX_COMPRESSION_RATIO`` of what it declares: no filter we write
  (gzip, deflate's limit is 1032:1) compresses that far, so its chunks were never written and reading it would
  allocate the declared size for fill values. Files are self-contained; our writers never produce any of these.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

import h5py

from .errors import FormatError, one_line

HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"
DEFAULT_MAX_DATASET_BYTES = 8 << 30
MAX_COMPRESSION_RATIO = 1100
MIN_CHECKED_BYTES = 1 << 20
_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISSOCK, "a socket"),
          (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"))


def regular_file(path, what: str) -> Path:
    """``path`` as a Path if it names a regular file (symbolic links followed); ``FormatError`` naming ``what`` was
    expected otherwise."""
    path = Path(path)
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        raise FormatError(f"{path}: no such file, expected {what}") from None
    except OSError as e:
        raise FormatError(f"{path}: cannot read ({one_line(e)}), expected {what}") from None
    if not stat.S_ISREG(mode):
        kind = next((name for test, name in _KINDS if test(mode)), "not a regular file")
        raise FormatError(f"{path}: is {kind}, not a regular file; expected {what}")
    return path


def read_head(path, n: int) -> bytes | None:
    """The first ``n`` bytes of ``path`` if it is a readable regular file, else ``None``; never raises."""
    try:
        if not stat.S_ISREG(os.stat(path).st_mode):
            return None
        with open(path, "rb") as fh:
            return fh.read(n)
    except (OSError, ValueError):
        return None


def max_dataset_bytes() -> int:
    """The largest dataset a reader accepts, in bytes (``KNIT_MAX_DATASET_BYTES``, default 8 GiB)."""
    from .memory_budget import bytes_setting

    limit = bytes_setting("KNIT_MAX_DATASET_BYTES")
    return DEFAULT_MAX_DATASET_BYTES if limit is None else limit


def _gib(n: int) -> str:
    return f"{n / (1 << 30):.3g} GiB" if n >= 1 << 30 else f"{n / (1 << 20):.3g} MiB"


def check_hdf5_storage(f: h5py.File, where: str) -> None:
    """Refuse external links, external or virtual storage and datasets that declare more than they can hold or
    than ``max_dataset_bytes()`` (module docstring); reads no dataset's data."""
    limit = max_dataset_bytes()

    def problem(name, link):  # a message stops the visit (raising inside h5py's visitor would be mangled)
        if isinstance(link, h5py.ExternalLink):
            return f"{name} is an external link to {link.filename!r}; files must be self-contained"
        if not isinstance(link, h5py.HardLink):
            return None  # a soft link names an object of this file, which is visited through its hard link
        obj = f[name]
        if not isinstance(obj, h5py.Dataset):
            return None
        if obj.external:
            return f"dataset {name} keeps its data in another file ({obj.external[0][0]!r}); files must be " \
                   f"self-contained"
        if obj.is_virtual:
            return f"dataset {name} is a virtual dataset (mapped from other files); files must be self-contained"
        declared = int(obj.size) * obj.dtype.itemsize
        if declared > limit:
            return f"dataset {name} declares shape {obj.shape} ({_gib(declared)}), more than the {_gib(limit)} a " \
                   f"reader accepts (KNIT_MAX_DATASET_BYTES)"
        if declared > MIN_CHECKED_BYTES:
            stored = obj.id.get_storage_size()
            if stored * MAX_COMPRESSION_RATIO < declared:
                return f"dataset {name} declares shape {obj.shape} ({_gib(declared)}) but stores {stored} bytes: " \
                       f"never written (no compression we use gives {declared / max(stored, 1):.3g}:1)"
        return None

    message = f.visititems_links(problem)
    if message is not None:
        raise FormatError(f"{where}: {message}")


def open_hdf5(path, what: str) -> h5py.File:
    """``path`` opened read-only after ``regular_file``, the HDF5 signature and ``check_hdf5_storage``; every
    failure is a one-line ``FormatError`` naming the file and ``what`` was expected."""
    path = regular_file(path, what)
    head = read_head(path, 8)
    if head is None:
        raise FormatError(f"{path}: cannot read, expected {what}")
    if head != HDF5_MAGIC:
        raise FormatError(f"{path}: not an HDF5 file (first bytes {head!r}), expected {what}")
    try:
        f = h5py.File(path, "r")
    except (OSError, ValueError) as e:
        raise FormatError(f"{path}: unreadable HDF5 (truncated or corrupt: {one_line(e)}), expected {what}") \
            from None
    try:
        check_hdf5_storage(f, str(path))
    except BaseException:
        f.close()
        raise
    return f
