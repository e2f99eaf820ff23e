"""BCC ("Binary Curve Collection", Cem Yuksel's cyCodeBase) files: one frame of 3-D curves, read and written.

Layout (little-endian, full table in ``YARN_CURVES.md``): a 64-byte header ``"BCC"``, byte-size byte ``0x44``
(4-byte int, 4-byte float: the only variant supported), 2-char curve type (``PL``, ``C0``, ``BS``, ``BZ``),
dimensions (must be 3), up axis (index of the up dimension: 0 x, 1 y, 2 z), uint64 curve count, uint64 total
control-point count, 40 bytes of free text; then per curve an int32 point count (negative: closed loop, first point
not repeated) followed by that many float32 xyz triples.

Conventions: a curve needs at least 2 points (|count| of 0 or 1 is rejected). BCC carries no units, yarn types or
time: ``read_bcc`` returns one frame, every curve of yarn type 0 named ``"unknown"``, ``units`` as the caller says
(default ``"unknown"``), ``frame_time`` None. The free text is never interpreted (other writers leave garbage in it);
``write_bcc`` fills it with a null-padded ASCII note and ``describe`` shows its printable prefix for information only.
"""

import struct

import numpy as np

from .atomic import atomic_path
from .errors import FormatError, read_problems
from .input_files import read_head, regular_file
from .yarn_curves import CURVE_TYPES, make_yarn_curves, summary, validate_curves

HEADER = struct.Struct("<3sB2sBBQQ40s")  # 64 bytes, no padding
MAGIC = b"BCC"
BYTE_SIZES = 0x44  # high nibble: bytes per int, low nibble: bytes per float
UP_AXES = ("x", "y", "z")


def _parse_header(data, where):
    if len(data) < HEADER.size:
        raise FormatError(f"{where}: truncated header: file has {len(data)} bytes, expected at least {HEADER.size}")
    magic, sizes, ctype, dims, up, n_curves, n_points, info = HEADER.unpack_from(data)
    if magic != MAGIC:
        raise FormatError(f"{where}: bad magic {magic!r}, expected {MAGIC!r} (not a BCC file)")
    if sizes != BYTE_SIZES:
        raise FormatError(f"{where}: byte-size byte 0x{sizes:02X} ({sizes >> 4}-byte int, {sizes & 15}-byte float), "
                          f"expected 0x44 (4-byte int, 4-byte float), the only variant supported")
    curve_type = ctype.decode("latin-1")
    if curve_type not in CURVE_TYPES:
        raise FormatError(f"{where}: curve type {ctype!r}, expected one of {', '.join(CURVE_TYPES)}")
    if dims != 3:
        raise FormatError(f"{where}: dimensions = {dims}, expected 3")
    if n_curves < 1:
        raise FormatError(f"{where}: header curve count is 0, expected at least one curve")
    expected = HEADER.size + 4 * n_curves + 12 * n_points
    if len(data) != expected:
        what = "truncated" if len(data) < expected else f"{len(data) - expected} trailing bytes"
        raise FormatError(f"{where}: {what}: file has {len(data)} bytes but the header counts ({n_curves} curves, "
                          f"{n_points} points) need {expected}")
    return {"curve_type": curve_type, "up": up, "curves": n_curves, "points": n_points, "info": info}


def _walk_counts(words, n_curves, n_points, where):
    """Word index of each curve's int32 count and the signed counts; checks them against the header totals."""
    starts = np.empty(n_curves, np.int64)
    counts = np.empty(n_curves, np.int64)
    pos = 0
    for c in range(n_curves):
        if pos == len(words):
            raise FormatError(f"{where}: curve {c}: the file ends after {c} of the header's {n_curves} curves "
                              f"(curve point counts add up to more than the header total {n_points})")
        n = int(words[pos])
        if abs(n) < 2:
            raise FormatError(f"{where}: curve {c}: point count {n}, expected at least 2 points (negative: closed)")
        if pos + 1 + 3 * abs(n) > len(words):
            raise FormatError(f"{where}: curve {c}: point count {n} runs past the end of the file "
                              f"(curve point counts add up to more than the header total {n_points})")
        starts[c], counts[c] = pos, n
        pos += 1 + 3 * abs(n)
    if pos != len(words):
        raise FormatError(f"{where}: curve point counts add up to {(pos - n_curves) // 3}, "
                          f"expected the header total {n_points}")
    return starts, counts


def read_bcc(path, units="unknown"):
    """Read a BCC file as a one-frame ``YarnCurves``; raise ``FormatError`` on any problem."""
    return _read(path, units)[1]


def _read(path, units):
    """The parsed header (dict) and the ``YarnCurves`` of a BCC file."""
    where = str(path)
    try:
        data = regular_file(path, "a BCC file").read_bytes()
    except OSError as e:
        raise FormatError(f"{where}: cannot read ({type(e).__name__}: {' '.join(str(e).split())})") from e
    head = _parse_header(data, where)
    words = np.frombuffer(data, "<i4", offset=HEADER.size)
    starts, counts = _walk_counts(words, head["curves"], head["points"], where)
    is_point = np.ones(len(words), bool)
    is_point[starts] = False
    points = words.view("<f4")[is_point].reshape(1, -1, 3).astype(np.float64)
    offsets = np.concatenate([[0], np.cumsum(np.abs(counts))])
    return head, make_yarn_curves(points, offsets, closed=counts < 0, curve_type=head["curve_type"], units=units,
                                  where=where)


def write_bcc(path, yc, frame=0, up_axis="y"):
    """Write frame ``frame`` of ``yc`` atomically as a BCC file (float32 points) with the given up axis (x, y, z)."""
    where = str(path)
    validate_curves(yc, where)
    if up_axis not in UP_AXES:
        raise FormatError(f"{where}: up_axis {up_axis!r}, expected one of {', '.join(UP_AXES)}")
    if not 0 <= frame < yc.points.shape[0]:
        raise FormatError(f"{where}: frame {frame}, expected 0 <= frame < {yc.points.shape[0]}")
    counts = np.diff(yc.offsets)
    if counts.max() >= 2**31:
        c = int(counts.argmax())
        raise FormatError(f"{where}: curve {c} has {counts[c]} points, expected fewer than 2**31 (int32 count)")
    points = yc.points[frame].astype(np.float32)  # validated to |coordinate| ≤ MAX_COORD: no float32 overflow
    n_curves, n_points = len(counts), len(points)
    words = np.empty(n_curves + 3 * n_points, "<i4")
    starts = 3 * yc.offsets[:-1] + np.arange(n_curves)
    is_point = np.ones(len(words), bool)
    is_point[starts] = False
    words[starts] = np.where(yc.closed, -counts, counts)
    words.view("<f4")[is_point] = points.ravel()
    info = f"knit-yarn-curves; units={yc.units}".encode("ascii", "replace")[:40]
    header = HEADER.pack(MAGIC, BYTE_SIZES, yc.curve_type.encode("ascii"), 3, UP_AXES.index(up_axis),
                         n_curves, n_points, info)
    with atomic_path(path) as tmp:
        tmp.write_bytes(header + words.tobytes())


def sniff(path):
    """True if ``path`` starts with the BCC magic ``b"BCC"``; never raises."""
    return read_head(path, 3) == MAGIC


def describe(path):
    """JSON-serializable summary of a BCC file; raises ``FormatError`` if the file is invalid."""
    head, yc = _read(path, "unknown")
    info = head["info"].split(b"\0", 1)[0]
    return {
        "kind": "bcc",
        "up_axis": UP_AXES[head["up"]] if head["up"] < 3 else f"unknown ({head['up']})",
        "info_text": "".join(chr(b) if 32 <= b < 127 else "?" for b in info),
        **summary(yc),
    }


def validate(path):
    """Problems found in a BCC file (empty list: valid); never raises for bad content."""
    return read_problems(read_bcc, path)
