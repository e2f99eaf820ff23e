"""Knitout (the textiles-lab machine-knitting instruction format) executed into a rest ``StitchMesh``.

We execute the instructions ourselves rather than through the PyPI ``knitout-interpreter`` /
``virtual-knitting-machine`` packages: what we need is which stitch each ``knit`` makes and which loops it pulls
through, about a hundred lines over a dictionary of needle stacks, while those packages model a whole machine
(carriers, hooks, float lengths) for validation and would add two dependencies for a part of them we can check in
tests against our own fixtures.

Execution (knitout specification, textiles-lab ``knitout.html``):

* Needles ``f<n>``/``b<n>`` hold stacks of loops. ``knit D N CS`` makes a stitch: it pulls a new loop through the
  loops on N (consuming them) and leaves the new loop on N; ``tuck`` on an empty needle adds a loop (a cast-on);
  either without carriers releases N's loops;
  ``xfer N N2`` moves N's loops onto N2; ``drop N`` releases them. ``rack``, ``miss``, ``in``, ``out``, ``inhook``,
  ``outhook``, ``releasehook``, ``stitch``, ``pause``, ``x-…`` extensions and comments change no loop.
* A stitch seen from the front of the fabric is a knit when made on the front bed and a purl on the back bed. Its
  column is its needle number (the fabric's left, seen from the front, is needle 0's side); its course is one more
  than that of the stitch whose loop it consumes (0 on a cast-on loop), i.e. stitches stack up their wale whatever
  pass made them.
* The result must be a fabric the simulator takes: every stitch consumes at most one loop (no decreases through
  stacked loops), and every course spans the same columns (no misses or floats leaving short wales). It is either
  one flat single-layer sheet (no column knit on both beds in one course), or a **tube**: every column knit on both
  beds in each course, each pass on one bed (front and back layers joined only round the edges) and no transfers.
  A tube becomes closed courses (knitting in the round, STITCH_MESH.md): round the outside, the front bed's needles
  left → right and then the back bed's right → left, all knit stitches (a back-bed stitch faces out of the tube's
  back), the yarn spiralling left → right seen from outside (a tube knitted the other way round is drawn as its
  mirror image, the same fabric for knit stitches). Other double-bed fabrics (interlock, Milano rib: both beds in
  one pass) are refused, as is anything else, in one line naming the knitout line. The stitches then become a knit
  chart and go through ``chart_to_mesh`` (its default stitch size).
"""

from __future__ import annotations

import re
from pathlib import Path

from data_formats.errors import FormatError, read_problems
from data_formats.input_files import read_head, regular_file
from knitrun.sim.knit_chart import chart_to_mesh

MAGIC = b";!knitout-"
_NEEDLE = re.compile(r"([fb])(-?\d+)$")
_IGNORED = {"rack", "miss", "in", "out", "inhook", "outhook", "releasehook", "stitch", "pause", "amiss"}


def _needle(token: str, where: str, lineno: int):
    m = _NEEDLE.match(token)
    if m is None:
        raise FormatError(f"{where}: line {lineno}: needle {token!r}, expected f<n> or b<n> (sliders fs/bs are not "
                          f"supported)")
    return m.group(1), int(m.group(2))


def knitout_chart(path) -> str:
    """The knit chart (``knitrun.sim.knit_chart`` syntax, top course first) of a knitout file (module docstring)."""
    return knitout_fabric(path)[0]


def knitout_fabric(path) -> tuple[str, bool]:
    """(knit chart, in the round) of a knitout file: the chart of a tube is its closed courses (module docstring)."""
    regular_file(path, "a knitout file")
    where = str(path)
    try:
        text = Path(path).read_text()
    except UnicodeDecodeError as e:
        raise FormatError(f"{where}: not a text knitout file ({e.reason} at byte {e.start})") from None
    if not text.startswith(";!knitout-"):
        raise FormatError(f"{where}: line 1 is not ';!knitout-N', expected a knitout file")
    stacks = {}  # needle → list of loops; a loop is the (course, line) of the stitch that made it, None: cast-on
    stitches = {}  # (course, bed, column) → line
    passes = []  # per pass (knits in one direction, uninterrupted by transfers or drops): (first line, beds)
    first_xfer, last_direction = None, None
    for lineno, line in enumerate(text.splitlines(), 1):
        tokens = line.split(";", 1)[0].split()
        if not tokens:
            continue
        op, args = tokens[0], tokens[1:]
        if op in _IGNORED or op.startswith("x-"):
            continue
        if op != "knit":
            last_direction = None
        if op in ("knit", "tuck"):
            if len(args) < 2 or args[0] not in ("+", "-"):
                raise FormatError(f"{where}: line {lineno}: {line.strip()!r:.60}, expected '{op} +|- needle "
                                  f"carriers'")
            needle = _needle(args[1], where, lineno)
            held = stacks.get(needle, [])
            if len(args) == 2:  # no carriers: no yarn, the loops are released (knitout: knit/tuck with an empty set)
                stacks.pop(needle, None)
                continue
            if op == "tuck":
                if held:
                    raise FormatError(f"{where}: line {lineno}: tuck on {args[1]} holding a loop (a tuck stitch): "
                                      f"not supported, only tucks that cast on")
                stacks[needle] = [None]
                continue
            if len(held) > 1:
                raise FormatError(f"{where}: line {lineno}: knit on {args[1]} holding {len(held)} loops (a decrease "
                                  f"through stacked loops): not supported")
            course = 0 if not held or held[0] is None else held[0] + 1
            if (course, needle[0], needle[1]) in stitches:
                raise FormatError(f"{where}: line {lineno}: needle {args[1]} knits course {course} twice (also line "
                                  f"{stitches[course, needle[0], needle[1]]})")
            stitches[course, needle[0], needle[1]] = lineno
            if args[0] != last_direction:
                passes.append((lineno, set()))
                last_direction = args[0]
            passes[-1][1].add(needle[0])
            stacks[needle] = [course]
        elif op == "xfer":
            if len(args) != 2:
                raise FormatError(f"{where}: line {lineno}: {line.strip()!r:.60}, expected 'xfer needle needle'")
            src, dst = _needle(args[0], where, lineno), _needle(args[1], where, lineno)
            stacks[dst] = stacks.get(dst, []) + stacks.pop(src, [])
            first_xfer = first_xfer or lineno
        elif op == "drop":
            if len(args) != 1:
                raise FormatError(f"{where}: line {lineno}: {line.strip()!r:.60}, expected 'drop needle'")
            stacks.pop(_needle(args[0], where, lineno), None)
        elif op == "split":
            raise FormatError(f"{where}: line {lineno}: split: not supported")
        else:
            raise FormatError(f"{where}: line {lineno}: {op!r} is not a knitout operation")
    if not stitches:
        raise FormatError(f"{where}: no knit operations, expected a knitted fabric")
    both = sorted((c, n) for c, b, n in stitches if b == "f" and (c, "b", n) in stitches)
    if both:  # a column knit on both beds in one course: a tube, or a fabric we cannot take
        mixed = next((first for first, beds in passes if len(beds) > 1), None)
        if mixed is not None:
            c, n = both[0]
            raise FormatError(f"{where}: line {stitches[c, 'b', n]}: column {n} is knit on both beds in course {c} "
                              f"(also line {stitches[c, 'f', n]}) and the pass from line {mixed} knits on both beds: "
                              f"a double-bed fabric (interlock, Milano rib), not supported; tubes knit each pass on "
                              f"one bed")
        if first_xfer is not None:
            raise FormatError(f"{where}: line {first_xfer}: a transfer in a tube (both beds knit every column): not "
                              f"supported")
    rows = {}
    for course, bed, column in stitches:
        rows.setdefault(course, {"f": set(), "b": set()})[bed].add(column)
    courses = max(rows) + 1
    columns = sorted({n for c in rows.values() for side in c.values() for n in side})
    full = list(range(columns[0], columns[-1] + 1))
    for course in range(courses):
        row = rows.get(course, {"f": set(), "b": set()})
        have = [sorted(row["f"]), sorted(row["b"])] if both else [sorted(row["f"] | row["b"])]
        for side in have:
            if side != full:
                missing = sorted(set(full) - set(side))
                raise FormatError(f"{where}: course {course} has no stitch in column(s) {missing[:5]}"
                                  f"{' …' if len(missing) > 5 else ''} of needles {columns[0]}..{columns[-1]}"
                                  f"{' on one bed of the tube' if both else ''}: not one rectangular "
                                  f"{'tube' if both else 'single-layer fabric'} (misses, floats or an unknit needle)")
    if both:  # round the outside: the front left → right, then the back right → left; all knit stitches
        return "\n".join("k" * (2 * len(full)) for _ in range(courses)), True
    symbol = {(c, n): "k" if b == "f" else "p" for c, b, n in stitches}
    return "\n".join("".join(symbol[course, col] for col in full) for course in reversed(range(courses))), False


def read_knitout(path, yarn_type: str = "cotton1"):
    """The rest ``StitchMesh`` of a knitout file (module docstring); FormatError (one line) naming the line."""
    chart, in_the_round = knitout_fabric(path)
    return chart_to_mesh(chart, yarn_type=yarn_type, where=str(path), in_the_round=in_the_round)


def sniff(path) -> bool:
    """True for a file starting with ';!knitout-'. Never raises."""
    return read_head(path, len(MAGIC)) == MAGIC


def describe(path) -> dict:
    from data_formats.stitch_mesh import summary

    return {"kind": "knitout", **summary(read_knitout(path))}


def validate(path) -> list[str]:
    return read_problems(read_knitout, path)
