"""Line-oriented text formats (OBJ, OBJ polylines, .smobj): the statement keywords a file uses, for sniffing, and
the ``v x y z`` statement they share."""

from __future__ import annotations

from .errors import FormatError
from .input_files import read_head

SNIFF_BYTES = 1 << 20


def statement_keys(path, limit: int = SNIFF_BYTES) -> set[str] | None:
    """First words of the complete, non-comment lines in the first ``limit`` bytes; None for an unreadable or binary
    file. Never raises."""
    head = read_head(path, limit)
    if not head or b"\0" in head:
        return None
    lines = head.decode("utf-8", errors="ignore").splitlines()
    if len(head) >= limit:
        lines = lines[:-1]  # the last line may be cut
    return {line.split(None, 1)[0] for line in lines if line.strip() and not line.lstrip().startswith("#")}


def parse_vertex(tokens: list[str], where: str, lineno: int, line: str, label: str = "") -> list[float]:
    """[x, y, z] of a ``v x y z`` statement (``tokens`` its words); FormatError naming the line (and ``label``)."""
    try:
        xyz = [float(t) for t in tokens[1:4]]
    except ValueError:
        xyz = []
    if len(xyz) != 3:
        raise FormatError(f"{where}: line {lineno}: {label}{line.strip()!r:.60}, expected 'v x y z'")
    return xyz
