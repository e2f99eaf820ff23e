"""How much memory one job may plan to use, so that legal but extreme inputs are refused in one line before an
allocation fails (or the machine swaps) minutes into the work.

``memory_limit()`` is ``KNIT_MAX_MEMORY_BYTES`` when set, else half the machine's physical memory (the rest is left
to the caller's other arrays, Embree and the OS). ``check_memory(nbytes, what, causes)`` raises a ``FormatError``
that names the estimate, the limit and the input fields that drive it. Estimates are upper bounds measured per
item (the estimating function says from what), not exact.
"""

from __future__ import annotations

import os

from .errors import FormatError


def bytes_setting(name: str) -> int | None:
    """A positive byte count from environment variable ``name`` (None when unset); FormatError naming it otherwise."""
    value = os.environ.get(name)
    if value is None:
        return None
    try:
        limit = int(float(value))
    except (ValueError, OverflowError):
        limit = 0
    if limit <= 0:
        raise FormatError(f"{name} = {value!r}: expected a positive number of bytes")
    return limit


def memory_limit() -> int:
    """Bytes one job may plan to allocate (module docstring)."""
    limit = bytes_setting("KNIT_MAX_MEMORY_BYTES")
    if limit is not None:
        return limit
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") // 2
    except (ValueError, OSError, AttributeError):
        return 8 << 30


def human_bytes(n: float) -> str:
    for unit, size in (("TiB", 1 << 40), ("GiB", 1 << 30), ("MiB", 1 << 20)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{n / 1024:.3g} KiB"


def check_memory(nbytes: float, what: str, causes: str) -> None:
    """Refuse work whose estimated peak ``nbytes`` exceeds ``memory_limit()``: one line naming ``what`` would be
    allocated and the ``causes`` (the input fields and values that make it so)."""
    limit = memory_limit()
    if nbytes > limit:
        raise FormatError(f"{what} would need ~{human_bytes(nbytes)} ({causes}), more than the "
                          f"{human_bytes(limit)} allowed (KNIT_MAX_MEMORY_BYTES; default half the machine's memory)")
