"""Knit charts (plain text) and named patterns, turned into a rest ``StitchMesh`` (spec: data_formats/STITCH_MESH.md).

Chart text:

* One line per course, one character per stitch, drawn as the stitch looks from the front (right side):
  ``k`` or ``.`` knit, ``p`` or ``-`` purl, ``o`` yarn-over, ``/`` k2tog (right-leaning decrease), ``\\`` ssk
  (left-leaning decrease).
* The first stitch line is the TOP course (knitted last) and the last line is course 0 (knitted first), as knitters
  draw charts. The first character of a line is the left of the fabric seen from the front: column 0, x = 0.
  Knitters read right-side rows right to left; our yarn instead runs course 0 left → right, course 1 right → left,
  ... (this orders faces along the yarn; it does not change the fabric).
* ``#`` starts a comment to the end of the line; blank lines are ignored; spaces and tabs inside a line are ignored.
* Each stitch consumes loops of the course below: knit and purl 1, yarn-over 0, decrease 2. A course must consume
  exactly the stitches of the course below it, so it is one stitch longer per yarn-over and one shorter per
  decrease; course 0 is worked into a cast-on of as many loops as it consumes. Errors name line and column.

Rest geometry (z = 0): boundary line ``b`` (b = 0 .. courses) lies at y = b * stitch_height with vertices at
x = 0, w, 2w, ... (w = stitch_width), one more vertex than the course below it has stitches (boundary 0: than course
0 consumes). Stitch i of course r is the face whose bottom vertices are those of the loops it consumes on boundary r
(a yarn-over has the single vertex where it sits between two loops: a triangle) and whose top edge is [i w, (i+1) w]
on boundary r+1. Rows are left-aligned as written, so stitches right of an unbalanced increase or decrease lean.

In the round (``in_the_round=True``, a tube): each line is one closed course read left → right seen from outside,
starting at the seam, and the yarn spirals (STITCH_MESH.md). Boundary ``b`` is a circle of as many vertices as it
has loops (n_b), of circumference n_b w: vertex k at angle θ = 2πk/n_b − π/2 is (R_b sin θ, b h, R_b cos θ) with
R_b = n_b w / (2π), so the tube's axis is y, the seam is at its left (x = −R_b) and the first half of each course
faces +z (for a knitout tube: the front bed faces the viewer). Every course needs at least 3 stitches.

Default stitch size: our guess sized for the cotton1 preset (yarn diameter about 2 * (ply_distance + ply semi-axis)
= 0.064 cm): a knit stitch is about 4 yarn diameters wide, 0.25 cm, i.e. 40 stitches per 10 cm, the fine end of the
Craft Yarn Council "lace" gauge range (33-40 sts / 10 cm); rows are 0.8 times as tall as stitches are wide (about 5
rows per 4 stitches, typical of stockinette), 0.2 cm.
"""

import math
import numbers

import numpy as np

from data_formats.errors import FormatError
from data_formats.stitch_mesh import LOOPS_CONSUMED, STITCH_TYPES, make_stitch_mesh

SYMBOLS = {"k": "knit", ".": "knit", "p": "purl", "-": "purl", "o": "yarn_over", "/": "k2tog", "\\": "ssk"}
SYMBOL_CODES = {ch: STITCH_TYPES.index(name) for ch, name in SYMBOLS.items()}
STITCH_WIDTH_CM = 0.25
STITCH_HEIGHT_CM = 0.2


def parse_chart(text, where="chart"):
    """Stitch-type codes (int8, index into ``STITCH_TYPES``) of every course, course 0 (the last line) first;
    ``FormatError`` naming line and column for a bad symbol or a course that does not fit the course below."""
    rows = []  # (line number, text columns, codes), top course first
    for lineno, line in enumerate(text.splitlines(), 1):
        cols, codes = [], []
        for col, ch in enumerate(line.split("#", 1)[0], 1):
            if ch in " \t":
                continue
            if ch not in SYMBOL_CODES:
                raise FormatError(f"{where}: line {lineno}, column {col}: {ch!r} is not a stitch symbol, expected "
                                  f"one of k . (knit) p - (purl) o (yarn-over) / (k2tog) \\ (ssk) or # (comment)")
            cols.append(col)
            codes.append(SYMBOL_CODES[ch])
        if codes:
            rows.append((lineno, cols, np.array(codes, np.int8)))
    if not rows:
        raise FormatError(f"{where}: no stitches, expected at least one line of stitch symbols")
    rows.reverse()
    for course in range(1, len(rows)):
        (lineno, cols, codes), below = rows[course], len(rows[course - 1][2])
        used = np.cumsum(LOOPS_CONSUMED[codes])
        rule = ("expected each course to consume exactly the stitches of the course below (knit/purl 1, yarn-over "
                "0, decrease 2)")
        over = np.flatnonzero(used > below)
        if over.size:
            i = over[0]
            raise FormatError(f"{where}: line {lineno}, column {cols[i]}: stitch {i + 1} of course {course} needs "
                              f"stitch {used[i]} of the course below (line {rows[course - 1][0]}), which has only "
                              f"{below}; {rule}")
        if used[-1] < below:
            raise FormatError(f"{where}: line {lineno}, column {cols[-1]}: course {course} ends having consumed "
                              f"{used[-1]} of the {below} stitches of the course below (line "
                              f"{rows[course - 1][0]}); {rule}")
    return [codes for _, _, codes in rows]


def chart_to_mesh(text, stitch_width=STITCH_WIDTH_CM, stitch_height=STITCH_HEIGHT_CM, units="cm",
                  yarn_type="cotton1", where="chart", in_the_round=False):
    """Rest ``StitchMesh`` of a chart (geometry in the module docstring; sizes in ``units``): faces in course-major
    order, left to right, one yarn of type ``yarn_type`` knitting course 0 left → right (in the round: a tube, the
    yarn spiralling left → right)."""
    for name, value in (("stitch_width", stitch_width), ("stitch_height", stitch_height)):
        if isinstance(value, bool) or not (isinstance(value, numbers.Real) and math.isfinite(value) and value > 0):
            raise FormatError(f"{where}: {name} = {value!r}, expected a positive finite length in {units}")
    courses = parse_chart(text, where)
    loops = [int(LOOPS_CONSUMED[courses[0]].sum())] + [len(codes) for codes in courses]  # loops on each boundary
    if in_the_round and min(loops) < 3:
        b = loops.index(min(loops))
        raise FormatError(f"{where}: {'the cast-on' if b == 0 else f'course {b - 1}'} has {loops[b]} loop(s), "
                          f"expected at least 3 stitches round a tube")
    counts = loops if in_the_round else [n + 1 for n in loops]  # vertices per boundary: a ring closes on itself
    base = np.concatenate([[0], np.cumsum(counts)])  # first vertex of each boundary line
    w, h = float(stitch_width), float(stitch_height)
    if in_the_round:
        rings = []
        for b, n in enumerate(counts):
            theta, radius = 2.0 * np.pi * np.arange(n) / n - 0.5 * np.pi, n * w / (2.0 * np.pi)
            rings.append(np.stack([radius * np.sin(theta), np.full(n, b * h), radius * np.cos(theta)], axis=1))
        vertices = np.concatenate(rings)
    else:
        vertices = np.concatenate([np.stack([np.arange(n) * w, np.full(n, b * h), np.zeros(n)], axis=1)
                                   for b, n in enumerate(counts)])
    face_vertices = []
    for r, codes in enumerate(courses):
        consumed = LOOPS_CONSUMED[codes]
        first_loop = np.cumsum(consumed) - consumed
        sizes = consumed + 3
        face = np.repeat(np.arange(len(codes)), sizes)
        slot = np.arange(sizes.sum()) - np.repeat(np.cumsum(sizes) - sizes, sizes)
        bottom = first_loop[face] + slot  # slots 0..b: bottom vertices left to right
        top = face + np.where(slot == consumed[face] + 1, 1, 0)  # then top-right, top-left
        if in_the_round:  # the last stitch's right vertices are the seam's
            bottom, top = bottom % counts[r], top % counts[r + 1]
        face_vertices.append(np.where(slot <= consumed[face], base[r] + bottom, base[r + 1] + top))
    stitch_type = np.concatenate(courses)
    offsets = np.concatenate([[0], np.cumsum(LOOPS_CONSUMED[stitch_type] + 3)])
    return make_stitch_mesh(vertices, offsets, np.concatenate(face_vertices), stitch_type, units, yarn_type, where)


def _stockinette(r, c):
    return np.full(r.shape, "k")


def _garter(r, c):
    return np.where(r % 2 == 0, "k", "p")  # knit every row: purl bumps on every other course seen from the front


def _rib1x1(r, c):
    return np.where(c % 2 == 0, "k", "p")


def _rib2x2(r, c):
    return np.where(c % 4 < 2, "k", "p")


def _seed(r, c):
    return np.where((r + c) % 2 == 0, "k", "p")


def _diamond(r, c):
    """One purl diamond on stockinette, its corners at the middles of the chart's edges (exclusive)."""
    hr, hc = max((r.shape[0] - 1) / 2, 0.5), max((r.shape[1] - 1) / 2, 0.5)
    return np.where(np.abs(r - (r.shape[0] - 1) / 2) / hr + np.abs(c - (r.shape[1] - 1) / 2) / hc < 1, "p", "k")


def _eyelet(r, c):
    """Stockinette with eyelet courses every 4 courses from course 2: "yo, k2tog" pairs (``o/``) and, every other
    time, "ssk, yo" pairs (``\\o``), one pair per 4 stitches from column 1; counts stay constant."""
    out = _stockinette(r, c)
    lace, whole_pair = r % 4 == 2, (c % 4 == 1) & (c + 1 < r.shape[1])
    mirrored = r % 8 == 6
    out[lace & whole_pair] = np.where(mirrored, "\\", "o")[lace & whole_pair]
    out[lace & (c % 4 == 2)] = np.where(mirrored, "o", "/")[lace & (c % 4 == 2)]
    return out


PATTERNS = {"stockinette": _stockinette, "garter": _garter, "rib1x1": _rib1x1, "rib2x2": _rib2x2, "seed": _seed,
            "diamond": _diamond, "eyelet": _eyelet}


def pattern_chart(name, rows, cols):
    """Chart text of the named pattern (a key of ``PATTERNS``) with ``rows`` courses of ``cols`` stitches."""
    if name not in PATTERNS:
        raise FormatError(f"pattern {name!r}: unknown, expected one of {', '.join(PATTERNS)}")
    for label, value in (("rows", rows), ("cols", cols)):
        if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < 1:
            raise FormatError(f"pattern {name}: {label} = {value!r}, expected an integer >= 1")
    r, c = np.mgrid[0:rows, 0:cols]
    grid = PATTERNS[name](r, c)
    lines = ["".join(row) for row in grid[::-1]]  # top course first
    return f"# {name}: {rows} courses x {cols} stitches; first line = top course\n" + "\n".join(lines) + "\n"
