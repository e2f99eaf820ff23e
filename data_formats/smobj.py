"""Augmented stitch meshes in the textiles-lab ``.smobj`` text format, read into a ``StitchMesh`` (STITCH_MESH.md,
"smobj").

The format (textiles-lab/smobj README): ``L name edge…`` face-library lines (edge labels in counter-clockwise order
from the bottom left, ``+``/``-`` giving the direction: ``lN`` N loops, ``yN`` N yarns, ``x`` empty), ``v x y z``
vertices, ``f`` faces of 1-based vertex indices (``/``-texture parts ignored), one ``T k`` per face (1-based index
into the library), ``e f/e f/e`` connections (1-based face/edge, a negative edge reversed), and optional ``N``
(knitout line), ``vt``/``vt2``/``tex`` (texture), ``U``/``c`` (yarn length checkpoints) lines, which carry nothing
the simulator uses.

What maps: the knitout library's plain stitches, one loop in and one out through one yarn —
``knit-to-left``/``knit-to-right`` → knit and ``purl-to-left``/``purl-to-right`` → purl, with edges
``-l1 ∓y1 +l1 ±y1``. Their edge order (bottom loop, right, top loop, left) is the quad order of our stitch faces.
Every other face type (tucks, splits, stacked loops lN, yarn routing and plating pieces) is refused with one line
naming the type and the line of its ``L`` and of the first face using it. Courses, columns and the yarn are derived
from the faces as for an OBJ stitch mesh (``make_stitch_mesh``: course 0 knitted left → right, then alternating);
each face's ``-to-left``/``-to-right`` must agree with that, and every ``e`` connection must pair the two edges our
derived adjacency pairs, else a one-line error names the face. Units are not in the format: ``units`` (default cm).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .errors import FormatError, read_problems
from .input_files import regular_file
from .text_statements import parse_vertex, statement_keys

PLAIN = {"knit": 0, "purl": 1}  # name prefix → stitch type code (STITCH_MESH.md)


def _face_type(name: str, edges: list[str]) -> tuple[int, int] | None:
    """(stitch type, yarn direction +1 right / −1 left) of a library entry the simulator supports, else None."""
    for prefix, code in PLAIN.items():
        for suffix, direction in (("-to-right", 1), ("-to-left", -1)):
            if name == prefix + suffix:
                yarn = "+y1" if direction == 1 else "-y1"
                back = "-y1" if direction == 1 else "+y1"
                if edges == ["-l1", yarn, "+l1", back]:
                    return code, direction
    return None


def read_smobj(path, units: str = "cm"):
    """The ``StitchMesh`` of an ``.smobj`` file (module docstring); FormatError (one line) naming the line, face or
    face type that does not map."""
    from .stitch_mesh import make_stitch_mesh, validate_stitch_mesh

    regular_file(path, "an .smobj stitch mesh")
    where = str(path)
    try:
        text = Path(path).read_text()
    except UnicodeDecodeError as e:
        raise FormatError(f"{where}: not a text .smobj file ({e.reason} at byte {e.start})") from None
    library, vertices, faces, types, connections = [], [], [], [], []
    for lineno, line in enumerate(text.splitlines(), 1):
        tokens = line.split("#", 1)[0].split()
        if not tokens:
            continue
        key, args = tokens[0], tokens[1:]
        try:
            if key == "L":
                if len(args) < 2:
                    raise ValueError
                library.append((args[0], args[1:], lineno))
            elif key == "v":
                vertices.append(parse_vertex(tokens, where, lineno, line))
            elif key == "f":
                idx = [int(t.split("/", 1)[0]) for t in args]
                if len(idx) < 3 or any(not 1 <= i <= len(vertices) for i in idx):
                    raise ValueError
                faces.append(([i - 1 for i in idx], lineno))
            elif key == "T":
                k = int(args[0])
                if len(args) != 1 or not 1 <= k <= len(library):
                    raise ValueError
                types.append((k - 1, lineno))
            elif key == "e":
                pairs = [tuple(int(x) for x in a.split("/")) for a in args]
                if len(pairs) != 2 or any(len(p) != 2 for p in pairs):
                    raise ValueError
                connections.append((pairs, lineno))
        except FormatError:
            raise
        except ValueError:
            raise FormatError(f"{where}: line {lineno}: {line.strip()!r:.60}, expected {_EXPECTED[key]}") from None
    if not faces:
        raise FormatError(f"{where}: no faces ('f' lines), expected an augmented stitch mesh")
    if len(types) != len(faces):
        raise FormatError(f"{where}: {len(faces)} faces and {len(types)} 'T' lines, expected one type per face")
    stitch, direction = [], []
    for f, ((k, lineno), (face, face_line)) in enumerate(zip(types, faces)):
        name, edges, l_line = library[k]
        mapped = _face_type(name, edges)
        if mapped is None:
            raise FormatError(f"{where}: line {face_line}: face {f + 1} has type {name!r} ({' '.join(edges)}, library "
                              f"line {l_line}), which the simulator does not support (it takes knit-to-left/right "
                              f"and purl-to-left/right with -l1 ±y1 +l1 ∓y1)")
        if len(face) != len(edges):
            raise FormatError(f"{where}: line {face_line}: face {f + 1} has {len(face)} vertices, its type {name!r} "
                              f"{len(edges)} edges")
        stitch.append(mapped[0])
        direction.append(mapped[1])
    offsets = np.concatenate([[0], np.cumsum([len(face) for face, _ in faces])])
    mesh = make_stitch_mesh(vertices, offsets, [i for face, _ in faces for i in face], stitch, units=units,
                            where=where)
    _check_directions(mesh, np.array(direction), faces, where)
    _check_connections(mesh, connections, len(faces), where)
    validate_stitch_mesh(mesh, where)
    return mesh


_EXPECTED = {"L": "'L name edge edge …'",
             "f": "'f' and at least 3 indices of vertices defined above", "T": "'T k' with k a library entry above",
             "e": "'e face/edge face/edge' (1-based)"}


def _check_directions(mesh, direction, faces, where):
    """Each face's -to-left/-to-right must be the direction the derived yarn takes through it."""
    along = np.empty(len(direction), np.int8)
    along[mesh.yarn_faces] = mesh.yarn_direction
    bad = np.flatnonzero(along != direction)
    if bad.size:
        f = int(bad[0])
        raise FormatError(f"{where}: line {faces[f][1]}: face {f + 1} (course {mesh.course[f]}) is knitted "
                          f"{'left' if direction[f] < 0 else 'right'}, but a flat knit's course {mesh.course[f]} runs "
                          f"{'left' if along[f] < 0 else 'right'} (course 0 left → right, then alternating)")


def _check_connections(mesh, connections, n_faces, where):
    """Every 'e' line pairs the edges our derived adjacency pairs (quads: 1 bottom, 2 right, 3 top, 4 left)."""
    partner = {}
    for f in range(n_faces):
        for edge, other, other_edge in ((2, mesh.course_right[f], 4), (3, mesh.wale_above[f], 1)):
            if other >= 0:
                partner[(f, edge)] = (int(other), other_edge)
                partner[(int(other), other_edge)] = (f, edge)
    for pairs, lineno in connections:
        (fa, ea), (fb, eb) = pairs
        if not (1 <= fa <= n_faces and 1 <= fb <= n_faces and 1 <= abs(ea) <= 4 and 1 <= abs(eb) <= 4):
            raise FormatError(f"{where}: line {lineno}: 'e {fa}/{ea} {fb}/{eb}' names a face or edge that does not "
                              f"exist ({n_faces} faces of 4 edges)")
        if partner.get((fa - 1, abs(ea))) != (fb - 1, abs(eb)):
            raise FormatError(f"{where}: line {lineno}: 'e {fa}/{ea} {fb}/{eb}' joins edges the faces' shared "
                              f"vertices do not (the mesh's positions and its connections disagree)")


def sniff(path) -> bool:
    """True for text whose first MiB has ``L``, ``f`` and ``T`` lines (an smobj). Never raises."""
    keys = statement_keys(path)
    return keys is not None and {"L", "f", "T"} <= keys


def describe(path) -> dict:
    from .stitch_mesh import summary

    return {"kind": "stitch-mesh-smobj", **summary(read_smobj(path))}


def validate(path) -> list[str]:
    return read_problems(read_smobj, path)
