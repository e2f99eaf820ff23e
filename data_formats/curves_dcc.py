"""Yarn curves for DCC tools: OBJ polylines in and out, USD BasisCurves out (``YARN_CURVES.md``, "DCC files").

OBJ (Wavefront, ``l`` statements)
---------------------------------
* Out (``write_obj_curves``): one frame; every control point a ``v x y z`` line (in the curves' units), every curve an
  ``l`` statement of its 1-based vertex indices, a closed curve repeating its first index at the end. A comment
  header records the units, curve type and yarn types; ``g <yarn type>`` groups the curves by yarn type. The
  control points are written whatever the curve type (OBJ polylines draw the control polygon).
* In (``read_obj_curves``): each ``l`` statement is a curve (indices 1-based, negative ones relative, ``/``-texture
  parts ignored), closed when its last index repeats its first; ``g``/``o`` names become yarn types (default
  ``unknown``); the header's ``# knit: units=… curve_type=…`` is honoured, else ``units`` and PL. At least one
  ``l`` with two or more points; anything else is a one-line ``FormatError`` naming the line.
* Recognised by content (``sniff_obj_curves``): ``v`` and ``l`` statements and no ``f``.

USD (``write_usd_curves``, through the ``usd-core`` bindings ``pxr``)
--------------------------------------------------------------------
* One ``UsdGeom.BasisCurves`` prim per wrap under ``/Yarns``: ``open`` (wrap ``pinned`` for the cubic types, which
  are evaluated through end points as our phantom points do; ``nonperiodic`` for linear and Bézier) and
  ``closed`` (wrap ``periodic``). Type ``linear`` for PL; ``cubic`` with basis ``catmullRom`` (C0), ``bspline`` (BS),
  ``bezier`` (BZ).
* ``points`` has one time sample per frame (time code = frame index; ``timeCodesPerSecond`` = 1 / ``frame_time``
  when the curves have one, else 24), ``curveVertexCounts`` the points per curve, ``widths`` the yarn **diameter**
  2r (constant), ``primvars:restArclength`` (float, vertex) the rest arc length so fiber textures stay put,
  ``primvars:yarnType`` (int, uniform) with the names in the prim's ``knit:yarnTypes`` custom data.
* ``metersPerUnit`` from the units; up axis Y.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from .atomic import atomic_path
from .conventions import CM_PER_UNIT, LENGTH_UNITS
from .errors import FormatError, read_problems
from .input_files import regular_file
from .text_statements import parse_vertex, statement_keys
from .yarn_curves import CURVE_TYPES, YarnCurves, make_yarn_curves, summary

_HEADER = re.compile(r"#\s*knit:\s*(.*)")
USD_TYPE = {"PL": ("linear", None), "C0": ("cubic", "catmullRom"), "BS": ("cubic", "bspline"),
            "BZ": ("cubic", "bezier")}


def write_obj_curves(path, yc: YarnCurves, frame: int = 0) -> None:
    """Frame ``frame`` of ``yc`` as OBJ polylines (module docstring), written atomically."""
    if not 0 <= frame < yc.points.shape[0]:
        raise FormatError(f"{path}: frame {frame}, expected 0 <= frame < {yc.points.shape[0]}")
    lines = [f"# knit: units={yc.units} curve_type={yc.curve_type} yarn_types={','.join(yc.yarn_types)}",
             f"# {len(yc.closed)} yarn curves, frame {frame}"]
    lines += [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in yc.points[frame]]
    for t, name in enumerate(yc.yarn_types):
        members = np.flatnonzero(yc.yarn_type == t)
        if members.size:
            lines.append(f"g {name}")
        for c in members:
            idx = list(range(yc.offsets[c] + 1, yc.offsets[c + 1] + 1))
            lines.append("l " + " ".join(map(str, idx + idx[:1] if yc.closed[c] else idx)))
    with atomic_path(path) as tmp:
        Path(tmp).write_text("\n".join(lines) + "\n")


def sniff_obj_curves(path) -> bool:
    """True for text whose first MiB has ``v`` and ``l`` statements and no ``f`` (OBJ polylines). Never raises."""
    keys = statement_keys(path)
    return keys is not None and {"v", "l"} <= keys and "f" not in keys


def describe_obj_curves(path) -> dict:
    """Summary for ``knitbake inspect``: the curves' statistics (``yarn_curves.summary``)."""
    return {"kind": "yarn-curves-obj", **summary(read_obj_curves(path))}


def validate_obj_curves(path) -> list[str]:
    """[] when ``read_obj_curves`` reads the file, else its one-line error."""
    return read_problems(read_obj_curves, path)


def read_obj_curves(path, units: str = "cm") -> YarnCurves:
    """Yarn curves of an OBJ's ``l`` statements (module docstring); FormatError (one line) naming the bad line."""
    regular_file(path, "an OBJ file of polylines")
    where = str(path)
    try:
        text = Path(path).read_text()
    except UnicodeDecodeError as e:
        raise FormatError(f"{where}: not a text OBJ file ({e.reason} at byte {e.start})") from None
    header, vertices, curves, groups, group = {}, [], [], [], "unknown"
    for lineno, line in enumerate(text.splitlines(), 1):
        if (m := _HEADER.match(line)) is not None:
            header.update(item.split("=", 1) for item in m.group(1).split() if "=" in item)
        tokens = line.split("#", 1)[0].split()
        if not tokens:
            continue
        if tokens[0] == "v":
            vertices.append(parse_vertex(tokens, where, lineno, line))
        elif tokens[0] in ("g", "o"):
            group = " ".join(tokens[1:]) or "unknown"
        elif tokens[0] == "l":
            try:
                idx = [int(t.split("/", 1)[0]) for t in tokens[1:]]
            except ValueError:
                idx = []
            idx = [i - 1 if i > 0 else len(vertices) + i for i in idx]
            if len(idx) < 2 or any(not 0 <= i < len(vertices) for i in idx):
                raise FormatError(f"{where}: line {lineno}: {line.strip()!r:.60}, expected 'l' and at least 2 "
                                  f"indices of vertices defined above (1..{len(vertices)})")
            closed = len(idx) > 2 and idx[0] == idx[-1]
            curves.append((idx[:-1] if closed else idx, closed, lineno))
            groups.append(group)
        elif tokens[0] == "f":
            raise FormatError(f"{where}: line {lineno}: a face ('f'): a mesh, not polylines (a stitch mesh OBJ "
                              f"goes with its .labels file)")
    if not curves:
        raise FormatError(f"{where}: no 'l' statements, expected OBJ polylines (one 'l' per yarn curve)")
    units = header.get("units", units)
    curve_type = header.get("curve_type", "PL")
    if units not in LENGTH_UNITS or curve_type not in CURVE_TYPES:
        raise FormatError(f"{where}: header units={units!r} curve_type={curve_type!r}, expected units in "
                          f"{', '.join(LENGTH_UNITS)} and curve_type in {', '.join(CURVE_TYPES)}")
    points = np.array([vertices[i] for idx, _, _ in curves for i in idx], np.float64)
    offsets = np.concatenate([[0], np.cumsum([len(idx) for idx, _, _ in curves])])
    names = list(dict.fromkeys(groups))
    return make_yarn_curves(points, offsets, closed=[c for _, c, _ in curves],
                            yarn_type=[names.index(g) for g in groups], yarn_types=names, curve_type=curve_type,
                            units=units, where=where)


def write_usd_curves(path, yc: YarnCurves, radius: float | None = None) -> None:
    """All frames of ``yc`` as USD BasisCurves (module docstring) at yarn radius ``radius`` (default: the curves'
    own; one of them is needed for the widths). ``.usda`` is text, ``.usd``/``.usdc`` binary crate. Written
    atomically."""
    from pxr import Usd

    radius = yc.radius if radius is None else radius
    if radius is None or not (np.isfinite(radius) and radius > 0):
        raise FormatError(f"{path}: the curves carry no yarn radius: give one (--radius R) for the USD widths")
    kind, basis = USD_TYPE[yc.curve_type]
    suffix = Path(path).suffix.lower()
    with atomic_path(path) as tmp:
        layer_path = Path(tmp).with_suffix(suffix)  # USD picks the file format by the extension
        try:
            _write_stage(Usd.Stage.CreateNew(str(layer_path)), yc, radius, kind, basis)
            layer_path.replace(tmp)
        finally:
            layer_path.unlink(missing_ok=True)


def _write_stage(stage, yc: YarnCurves, radius: float, kind: str, basis: str | None) -> None:
    from pxr import Sdf, Usd, UsdGeom, Vt

    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, CM_PER_UNIT[yc.units] / 100.0)
    frames = yc.points.shape[0]
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(frames - 1)
    stage.SetTimeCodesPerSecond(1.0 / yc.frame_time if yc.frame_time else 24.0)
    root = UsdGeom.Xform.Define(stage, "/Yarns")
    stage.SetDefaultPrim(root.GetPrim())
    counts = np.diff(yc.offsets)
    closed = np.asarray(yc.closed, bool)
    for name, members in (("open", np.flatnonzero(~closed)), ("closed", np.flatnonzero(closed))):
        if not members.size:
            continue
        curves = UsdGeom.BasisCurves.Define(stage, f"/Yarns/{name}")
        curves.CreateTypeAttr(kind)
        if basis:
            curves.CreateBasisAttr(basis)
        curves.CreateWrapAttr("periodic" if name == "closed" else
                              ("pinned" if basis in ("catmullRom", "bspline") else "nonperiodic"))
        index = np.concatenate([np.arange(yc.offsets[c], yc.offsets[c + 1]) for c in members])
        curves.CreateCurveVertexCountsAttr(Vt.IntArray(counts[members].tolist()))
        points = curves.CreatePointsAttr()
        for t in range(frames):
            points.Set(Vt.Vec3fArray.FromNumpy(yc.points[t, index].astype(np.float32)), Usd.TimeCode(t))
        curves.CreateWidthsAttr(Vt.FloatArray([2.0 * float(radius)]))
        curves.SetWidthsInterpolation(UsdGeom.Tokens.constant)
        api = UsdGeom.PrimvarsAPI(curves)
        api.CreatePrimvar("restArclength", Sdf.ValueTypeNames.FloatArray, UsdGeom.Tokens.vertex).Set(
            Vt.FloatArray.FromNumpy(yc.rest_arclength[index].astype(np.float32)))
        api.CreatePrimvar("yarnType", Sdf.ValueTypeNames.IntArray, UsdGeom.Tokens.uniform).Set(
            Vt.IntArray(yc.yarn_type[members].tolist()))
        curves.GetPrim().SetCustomDataByKey("knit:yarnTypes", Vt.StringArray(list(yc.yarn_types)))
        curves.GetPrim().SetCustomDataByKey("knit:curveType", yc.curve_type)
    stage.GetRootLayer().Save()
