"""Yarn curves in memory (``YarnCurves``) and in our HDF5 file (``format = "knit-yarn-curves"``, version 1.0).

Conventions (the full spec is ``YARN_CURVES.md``):

* Coordinates are in ``units`` (a length unit name, e.g. ``"cm"``); time is in seconds (``frame_time`` per frame).
* All curves are concatenated: curve ``c`` is ``points[:, offsets[c]:offsets[c+1]]``, at least 2 points each.
* A closed curve does NOT repeat its first point; the segment from its last point back to its first is implied.
* Points are control points of the curve type ``curve_type``: ``"PL"`` polyline, ``"C0"`` uniform Catmull-Rom,
  ``"BS"`` uniform cubic B-spline, ``"BZ"`` cubic Bézier (open: 3k+1 points, closed: 3k points).
* ``rest_arclength`` is the cumulative length of each curve's control polygon at frame 0 (0 at the first point of
  every curve, non-decreasing), fixed over frames.
* ``radius`` (optional): the yarn radius the curves were built for (the knot simulator's r), in ``units``; None
  when unknown. Tools that judge or draw the curves (the contact statistic, a renderer) read it.
* On disk, points are float32 (the precision the GPU and BCC use; half the size of float64 for long animations);
  the reader also accepts float64. In memory they are always float64.
"""

import dataclasses

import h5py
import numpy as np

from .atomic import atomic_path
from .conventions import MAX_COORD
from .errors import FormatError, read_problems
from .hdf5_fields import check_format_attrs, dataset, sniff_hdf5, str_attr, string_dataset
from .input_files import open_hdf5

FORMAT_NAME = "knit-yarn-curves"
FORMAT_VERSION = "1.1"  # 1.1 adds the optional ``radius`` attribute
CURVE_TYPES = ("PL", "C0", "BS", "BZ")



@dataclasses.dataclass
class YarnCurves:
    """Control points of C curves over T frames; see the module docstring for the conventions."""

    points: np.ndarray  # float64 (T, P, 3)
    offsets: np.ndarray  # int64 (C+1,)
    closed: np.ndarray  # bool (C,)
    yarn_type: np.ndarray  # int32 (C,), index into yarn_types
    yarn_types: list  # list[str]
    rest_arclength: np.ndarray  # float64 (P,)
    curve_type: str  # one of CURVE_TYPES
    units: str
    frame_time: float | None  # seconds per frame
    radius: float | None = None  # yarn radius the curves were built for, in units


def make_yarn_curves(points, offsets, closed=None, yarn_type=None, yarn_types=None, rest_arclength=None,
                     curve_type="C0", units="cm", frame_time=None, where="yarn curves", radius=None):
    """Build and validate a ``YarnCurves``, converting dtypes; ``points`` may be (P, 3) for a single frame.

    Defaults: all curves open, all of yarn type 0 named ``"unknown"``, ``rest_arclength`` from frame 0.
    """
    points = np.asarray(points, dtype=np.float64)
    if points.ndim == 2:
        points = points[None]
    offsets = np.asarray(offsets, dtype=np.int64)
    n_curves = max(len(offsets) - 1, 0)
    closed = np.zeros(n_curves, bool) if closed is None else np.asarray(closed, dtype=bool)
    yarn_type = np.zeros(n_curves, np.int32) if yarn_type is None else np.asarray(yarn_type, dtype=np.int32)
    yarn_types = ["unknown"] if yarn_types is None else list(yarn_types)
    if rest_arclength is None:
        _check_points(points, offsets, where)
        rest_arclength = control_polygon_arclength(points[0], offsets)
    yc = YarnCurves(points, offsets, closed, yarn_type, yarn_types, np.asarray(rest_arclength, dtype=np.float64),
                    curve_type, units, None if frame_time is None else float(frame_time),
                    None if radius is None else float(radius))
    validate_curves(yc, where)
    return yc


def control_polygon_arclength(frame_points, offsets):
    """Cumulative control-polygon length (P,) of each curve of one frame (P, 3), restarting at 0 per curve."""
    seg = np.zeros(len(frame_points))
    seg[1:] = np.linalg.norm(np.diff(frame_points, axis=0), axis=1)
    seg[offsets[:-1]] = 0.0  # no segment joins one curve to the next
    cum = np.cumsum(seg)
    return cum - np.repeat(cum[offsets[:-1]], np.diff(offsets))


def validate_curves(yc, where="yarn curves"):
    """Raise ``FormatError`` (message prefixed by ``where``) if ``yc`` breaks any convention of the module docstring."""
    _check_points(yc.points, yc.offsets, where)
    n_points, n_curves = yc.points.shape[1], len(yc.offsets) - 1
    for name, dtype in (("closed", np.bool_), ("yarn_type", np.int32)):
        arr = getattr(yc, name)
        if not isinstance(arr, np.ndarray) or arr.dtype != dtype or arr.shape != (n_curves,):
            raise FormatError(f"{where}: {name}: got {_shape_dtype(arr)}, expected {np.dtype(dtype)} ({n_curves},)")
    if not isinstance(yc.yarn_types, list) or not yc.yarn_types or not all(isinstance(s, str) for s in yc.yarn_types):
        raise FormatError(f"{where}: yarn_types: got {yc.yarn_types!r:.80}, expected a non-empty list of str")
    bad = np.flatnonzero((yc.yarn_type < 0) | (yc.yarn_type >= len(yc.yarn_types)))
    if bad.size:
        raise FormatError(f"{where}: yarn_type[{bad[0]}] = {yc.yarn_type[bad[0]]}, "
                          f"expected an index in [0, {len(yc.yarn_types)}) into yarn_types")
    _check_arclength(yc.rest_arclength, yc.offsets, n_points, where)
    if yc.curve_type not in CURVE_TYPES:
        raise FormatError(f"{where}: curve_type: got {yc.curve_type!r}, expected one of {', '.join(CURVE_TYPES)}")
    if yc.curve_type == "BZ":
        counts = np.diff(yc.offsets)
        bad = np.flatnonzero(np.where(yc.closed, counts % 3, (counts - 1) % 3) != 0)
        if bad.size:
            c = bad[0]
            raise FormatError(f"{where}: curve {c}: {'closed' if yc.closed[c] else 'open'} Bézier curve has "
                              f"{counts[c]} points, expected {'3k' if yc.closed[c] else '3k+1'}")
    if not isinstance(yc.units, str) or not yc.units:
        raise FormatError(f"{where}: units: got {yc.units!r}, expected a non-empty unit name such as 'cm'")
    if yc.frame_time is not None and not (isinstance(yc.frame_time, float) and np.isfinite(yc.frame_time)
                                          and yc.frame_time > 0):
        raise FormatError(f"{where}: frame_time: got {yc.frame_time!r}, expected None or a positive finite float")
    if yc.radius is not None and not (isinstance(yc.radius, float) and np.isfinite(yc.radius) and yc.radius > 0):
        raise FormatError(f"{where}: radius: got {yc.radius!r}, expected None or a positive finite float")


def _shape_dtype(arr):
    return f"{arr.dtype} {arr.shape}" if isinstance(arr, np.ndarray) else type(arr).__name__


def _check_points(points, offsets, where):
    if not isinstance(points, np.ndarray) or points.dtype != np.float64 or points.ndim != 3 or points.shape[2] != 3 \
            or points.shape[0] < 1:
        raise FormatError(f"{where}: points: got {_shape_dtype(points)}, expected float64 (T>=1, P, 3)")
    if not isinstance(offsets, np.ndarray) or offsets.dtype != np.int64 or offsets.ndim != 1 or len(offsets) < 2:
        raise FormatError(f"{where}: offsets: got {_shape_dtype(offsets)}, expected int64 (C+1,) with C >= 1")
    if offsets[0] != 0 or offsets[-1] != points.shape[1]:
        raise FormatError(f"{where}: offsets: runs from {offsets[0]} to {offsets[-1]}, "
                          f"expected 0 to the point count {points.shape[1]}")
    counts = np.diff(offsets)
    bad = np.flatnonzero(counts < 2)
    if bad.size:
        raise FormatError(f"{where}: curve {bad[0]}: offsets give {counts[bad[0]]} points, expected at least 2 "
                          f"(offsets must increase by >= 2)")
    check_finite(points, offsets, where)


def check_finite(points, offsets, where, first_frame=0):
    """Raise ``FormatError`` naming frame, curve and point of the first non-finite coordinate, or one beyond
    ±MAX_COORD, of (T, P, 3) points (whose frame 0 is frame ``first_frame`` of the caller's data)."""
    finite = np.isfinite(points).all(axis=2)
    if not finite.all():
        t, p = np.argwhere(~finite)[0]
        c = int(np.searchsorted(offsets, p, side="right") - 1)
        x, y, z = points[t, p]
        raise FormatError(f"{where}: frame {first_frame + t}, curve {c}, point {p - offsets[c]}: coordinates "
                          f"({x}, {y}, {z}) are not finite, expected finite numbers")
    big = np.abs(points).max(axis=2) > MAX_COORD
    if big.any():
        t, p = np.argwhere(big)[0]
        c = int(np.searchsorted(offsets, p, side="right") - 1)
        x, y, z = points[t, p]
        raise FormatError(f"{where}: frame {first_frame + t}, curve {c}, point {p - offsets[c]}: coordinates "
                          f"({x}, {y}, {z}), expected numbers in [{-MAX_COORD:g}, {MAX_COORD:g}]")


def _check_arclength(arc, offsets, n_points, where):
    if not isinstance(arc, np.ndarray) or arc.dtype != np.float64 or arc.shape != (n_points,):
        raise FormatError(f"{where}: rest_arclength: got {_shape_dtype(arc)}, expected float64 ({n_points},)")
    bad = np.flatnonzero(~np.isfinite(arc))
    if bad.size:
        raise FormatError(f"{where}: rest_arclength[{bad[0]}] = {arc[bad[0]]}, expected a finite number")
    bad = np.flatnonzero(arc[offsets[:-1]] != 0)
    if bad.size:
        raise FormatError(f"{where}: curve {bad[0]}: rest_arclength starts at {arc[offsets[bad[0]]]}, expected 0")
    step = np.diff(arc)
    step[offsets[1:-1] - 1] = 0.0  # curve boundaries may step down
    bad = np.flatnonzero(step < 0)
    if bad.size:
        p = bad[0] + 1
        c = int(np.searchsorted(offsets, p, side="right") - 1)
        raise FormatError(f"{where}: curve {c}, point {p - offsets[c]}: rest_arclength decreases from {arc[p - 1]} "
                          f"to {arc[p]}, expected non-decreasing along each curve")


def summary(yc):
    """JSON-serializable statistics of ``yc`` shared by the ``describe`` functions of both file formats."""
    p0 = yc.points[0]
    first, last = yc.offsets[:-1], yc.offsets[1:] - 1
    closing = np.linalg.norm(p0[first] - p0[last], axis=1)[yc.closed].sum()
    return {
        "curves": len(first),
        "points": int(yc.points.shape[1]),
        "frames": int(yc.points.shape[0]),
        "closed_curves": int(yc.closed.sum()),
        "curve_type": yc.curve_type,
        "units": yc.units,
        "frame_time": yc.frame_time,
        "radius": yc.radius,
        "bounds": [yc.points.min(axis=(0, 1)).tolist(), yc.points.max(axis=(0, 1)).tolist()],
        "yarn_types": list(yc.yarn_types),
        "curves_per_yarn_type": np.bincount(yc.yarn_type, minlength=len(yc.yarn_types)).tolist(),
        "total_length": float(control_polygon_arclength(p0, yc.offsets)[last].sum() + closing),
    }


def write_yarn_curves(path, yc):
    """Validate ``yc`` and write it atomically as a knit-yarn-curves HDF5 file (points stored as float32)."""
    validate_curves(yc, str(path))
    points32 = yc.points.astype(np.float32)  # validated to |coordinate| ≤ MAX_COORD: no float32 overflow
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        f.attrs["format"] = FORMAT_NAME
        f.attrs["version"] = FORMAT_VERSION
        f.attrs["units"] = yc.units
        f.attrs["curve_type"] = yc.curve_type
        if yc.frame_time is not None:
            f.attrs["frame_time"] = yc.frame_time
        if yc.radius is not None:
            f.attrs["radius"] = yc.radius
        f.create_dataset("points", data=points32)
        f.create_dataset("offsets", data=yc.offsets)
        f.create_dataset("closed", data=yc.closed.astype(np.uint8))
        f.create_dataset("yarn_type", data=yc.yarn_type)
        f.create_dataset("rest_arclength", data=yc.rest_arclength)
        f.create_dataset("yarn_types", data=np.array(yc.yarn_types, dtype=object), dtype=h5py.string_dtype())


def read_yarn_curves(path):
    """Read and fully validate a knit-yarn-curves HDF5 file; raise ``FormatError`` on any problem."""
    where = str(path)
    with open_hdf5(path, "a knit-yarn-curves file") as f:
        check_format_attrs(f, where, FORMAT_NAME, FORMAT_VERSION)
        points = dataset(f, "points", "f", where)
        if points.dtype not in (np.float32, np.float64):
            raise FormatError(f"{where}: points: dtype {points.dtype}, expected float32 or float64")
        closed = dataset(f, "closed", "biu", where)
        if closed.size and not np.isin(closed, (0, 1)).all():
            raise FormatError(f"{where}: closed: values {sorted(set(np.unique(closed).tolist()))[:4]}, expected 0 or 1")
        yarn_type = dataset(f, "yarn_type", "iu", where)
        if yarn_type.size and (yarn_type.min() < -2**31 or yarn_type.max() >= 2**31):
            raise FormatError(f"{where}: yarn_type: values outside int32, expected indices into yarn_types")
        yarn_types = string_dataset(f, "yarn_types", where)
        frame_time = f.attrs.get("frame_time")
        if frame_time is not None and not (np.ndim(frame_time) == 0 and np.issubdtype(type(frame_time), np.number)):
            raise FormatError(f"{where}: attribute frame_time: got {frame_time!r:.40}, expected a number of seconds")
        radius = f.attrs.get("radius")
        if radius is not None and not (np.ndim(radius) == 0 and np.issubdtype(type(radius), np.number)):
            raise FormatError(f"{where}: attribute radius: got {radius!r:.40}, expected a yarn radius in units")
        yc = YarnCurves(
            points=points.astype(np.float64),
            offsets=dataset(f, "offsets", "iu", where).astype(np.int64),
            closed=closed.astype(bool),
            yarn_type=yarn_type.astype(np.int32),
            yarn_types=yarn_types,
            rest_arclength=dataset(f, "rest_arclength", "f", where).astype(np.float64),
            curve_type=str_attr(f, "curve_type", where),
            units=str_attr(f, "units", where),
            frame_time=None if frame_time is None else float(frame_time),
            radius=None if radius is None else float(radius),
        )
    validate_curves(yc, where)
    return yc


def sniff(path):
    """True if ``path`` is an HDF5 file whose root attribute ``format`` is ``"knit-yarn-curves"``; never raises."""
    return sniff_hdf5(path, FORMAT_NAME)


def describe(path):
    """JSON-serializable summary of a knit-yarn-curves file; raises ``FormatError`` if the file is invalid."""
    yc = read_yarn_curves(path)
    with open_hdf5(path, "a knit-yarn-curves file") as f:
        version, points_dtype = str_attr(f, "version", str(path)), str(f["points"].dtype)
    return {"kind": "yarn-curves", "version": version, "points_dtype": points_dtype, **summary(yc)}


def validate(path):
    """Problems found in a knit-yarn-curves file (empty list: valid); never raises for bad content."""
    return read_problems(read_yarn_curves, path, any_error=True)
