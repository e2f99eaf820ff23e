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
* The result must be one flat single-layer fabric the simulator takes: every stitch consumes at most one loop (no
  decreases through stacked loops), the same column is never knit on both beds in one course (double-bed fabrics:
  interlock, Milano rib, tubes), and every course spans the same columns (no misses or floats leaving short wales).
  Anything else is refused in one line naming the knitout line. The stitches then become a knit chart and go
  through ``chart_to_mesh`` (its default stitch size).
"""

from __future__ import annotations

import re
from pathlib import Path

from data_formats.errors import FormatError
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
    regular_file(path, "a knitout file")
    where = str(path)
    try:
        text = Path(path).read_text()
    except UnicodeDecodeError as e:
        raise FormatError(f"{where}: not a text knitout file ({e.reason} at byte {e.start})") from None
    if not text.startswith(";!knitout-"):
        raise FormatError(f"{where}: line 1 is not ';!knitout-N', expected a knitout file")
    stacks = {}  # needle → list of loops; a loop is the (course, line) of the stitch that made it, None: cast-on
    stitches = {}  # (course, column) → (symbol, line)
    for lineno, line in enumerate(text.splitlines(), 1):
        tokens = line.split(";", 1)[0].split()
        if not tokens:
            continue
        op, args = tokens[0], tokens[1:]
        if op in _IGNORED or op.startswith("x-"):
            continue
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
            column = needle[1]
            if (course, column) in stitches:
                raise FormatError(f"{where}: line {lineno}: column {column} is knit twice in course {course} (also "
                                  f"line {stitches[course, column][1]}): a double-bed fabric (interlock, tube), not "
                                  f"supported")
            stitches[course, column] = ("k" if needle[0] == "f" else "p", lineno)
            stacks[needle] = [course]
        elif op == "xfer":
            if len(args) != 2:
                raise FormatError(f"{where}: line {lineno}: {line.strip()!r:.60}, expected 'xfer needle needle'")
            src, dst = _needle(args[0], where, lineno), _needle(args[1], where, lineno)
            stacks[dst] = stacks.get(dst, []) + stacks.pop(src, [])
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
    courses = max(c for c, _ in stitches) + 1
    columns = sorted({col for _, col in stitches})
    for course in range(courses):
        row = sorted(col for c, col in stitches if c == course)
        if row != columns or columns != list(range(columns[0], columns[-1] + 1)):
            missing = sorted(set(range(columns[0], columns[-1] + 1)) - set(row))
            raise FormatError(f"{where}: course {course} has no stitch in column(s) {missing[:5]}"
                              f"{' …' if len(missing) > 5 else ''} of needles {columns[0]}..{columns[-1]}: not one "
                              f"rectangular single-layer fabric (misses, floats or an unknit needle)")
    return "\n".join("".join(stitches[course, col][0] for col in columns) for course in reversed(range(courses)))


def read_knitout(path, yarn_type: str = "cotton1"):
    """The rest ``StitchMesh`` of a knitout file (module docstring); FormatError (one line) naming the line."""
    return chart_to_mesh(knitout_chart(path), yarn_type=yarn_type, where=str(path))


def sniff(path) -> bool:
    """True for a file starting with ';!knitout-'. Never raises."""
    return read_head(path, len(MAGIC)) == MAGIC


def describe(path) -> dict:
    from data_formats.stitch_mesh import summary

    return {"kind": "knitout", **summary(read_knitout(path))}


def validate(path) -> list[str]:
    try:
        read_knitout(path)
    except FormatError as e:
        return [str(e)]
    return []
