"""Atomic file writes: write to a temporary file in the destination folder, then rename over the target.

* A failure (exception, interrupt) while writing leaves no file at the destination and removes the temporary.
* The file gets the mode a plain ``open(path, "w")`` would give it: an existing file's mode when it replaces one,
  else 0666 less the process's umask (the temporary itself is created 0600 by ``mkstemp`` and changed just before
  the rename).
* A destination that is a symbolic link is written through: the file it points to is replaced, the link kept.
* Temporaries are named ``.<name>.<pid>.<random>.tmp``: writers of one path never share one (two bakes of a yarn
  may write the same cache entry at once; the last rename wins, both succeed), and a temporary left by a killed
  process (SIGKILL runs no cleanup) is removed by the next write to that path once its process is gone.
"""

import contextlib
import os
import re
import stat
import tempfile
import threading
from pathlib import Path

_UMASK_LOCK = threading.Lock()


def _umask() -> int:
    """The process's umask: from /proc/self/status where Linux gives it (read-only), else by setting and restoring
    it under a lock (a file another thread creates in that instant would get 0022)."""
    with contextlib.suppress(OSError, ValueError):
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    with _UMASK_LOCK:
        mask = os.umask(0o022)
        os.umask(mask)
    return mask


def new_file_mode(path) -> int:
    """The permission bits ``open(path, "w")`` leaves: the existing file's, else 0666 & ~umask."""
    try:
        return stat.S_IMODE(os.stat(path).st_mode)
    except OSError:
        return 0o666 & ~_umask()


def _remove_stale_temporaries(path: Path) -> None:
    """Delete ``.<name>.<pid>.*.tmp`` files beside ``path`` whose process no longer exists."""
    pattern = re.compile(re.escape(f".{path.name}.") + r"(\d+)\.[^.]+\.tmp$")
    with contextlib.suppress(OSError):
        for entry in os.scandir(path.parent if str(path.parent) else "."):
            match = pattern.match(entry.name)
            if match is None or int(match.group(1)) == os.getpid():
                continue
            try:
                os.kill(int(match.group(1)), 0)
            except ProcessLookupError:
                with contextlib.suppress(OSError):
                    os.unlink(entry.path)
            except (PermissionError, OverflowError):  # another user's live process, or not a pid of ours
                pass


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path next to ``path``; on success give it ``new_file_mode(path)`` and rename it to
    ``path``, on failure delete it."""
    path = Path(path)
    if path.is_symlink():  # write through the link, as open(path, "w") would, instead of replacing the link
        path = Path(os.path.realpath(path))
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        from .errors import FormatError

        raise FormatError(f"{path}: output folder {parent} does not exist")
    _remove_stale_temporaries(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.{os.getpid()}.", suffix=".tmp", dir=parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, new_file_mode(path))
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
