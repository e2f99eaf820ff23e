"""Asset-pack checks shared by the writer, the reader and the validator, so what one accepts the others accept:
one attribute (``attr_problem``, ``extra_attr_problem``) and its on-disk encoding (``encode_attr``,
``encode_extra``), a table's axis attributes (``axis_attrs``) and metadata (``table_meta_problems``), the shapes of
all tables together (``shape_problems``), a table's values (``numeric_problems``) and per-entry errors
(``stderr_problems``), and the small value helpers they use (``py``, ``is_real``, ``short``)."""

from __future__ import annotations

import datetime
import json
import math
import re
import sys

import h5py
import numpy as np

from ..conventions import LENGTH_UNITS, cell_centres
from ..errors import FormatError
from .schema import (AXES, DISK_AXIS_NAME, POSITIVE, SCHEMA_VERSION, STDERR_SUFFIX, TABLE_DTYPE, WRAPS, AttrSpec,
                     TableSpec)

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


# --- small helpers ------------------------------------------------------------------------------------------------

def py(value):
    """An attribute value as plain Python (str for strings, list[str] for string arrays, ndarray for numbers)."""
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    if isinstance(value, np.ndarray):
        if value.dtype.kind in "OSU":
            return [py(v) for v in value.tolist()]
        return value
    if isinstance(value, np.generic):
        return value.item()
    return value


def _is_int(v) -> bool:
    return isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_))


def is_real(v) -> bool:
    """True for a real number (Python or NumPy int or float), False for bool and everything else."""
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_))


def short(value, limit=60) -> str:
    """``value`` as a one-line repr of at most ``limit`` characters, for problem messages."""
    text = repr(value.tolist() if isinstance(value, np.ndarray) else value)
    text = " ".join(text.split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def raise_problems(path, probs):
    """Raise one FormatError naming ``path``, the first of ``probs`` and how many more there are; nothing if none."""
    if probs:
        more = f" (and {len(probs) - 1} more problem(s))" if len(probs) > 1 else ""
        raise FormatError(f"{path}: {probs[0]}{more}")


def _json_leaves_ok(obj, leaf_ok) -> bool:
    if isinstance(obj, dict):
        return all(isinstance(k, str) and _json_leaves_ok(v, leaf_ok) for k, v in obj.items())
    if isinstance(obj, list):
        return all(_json_leaves_ok(v, leaf_ok) for v in obj)
    return leaf_ok(obj)


def attr_problem(spec: AttrSpec, value, on_disk: bool):
    """Check one attribute. Returns (normalized Python value, problem text or None). ``value`` is what the writer
    was given (on_disk=False; JSON kinds may be dict or str) or what was read (on_disk=True)."""
    value = py(value)
    k = spec.kind
    if k == "const":
        return value, None if value == spec.value else f"is {short(value)}, expected {spec.value!r}"
    if k == "version":
        if not isinstance(value, str) or not re.fullmatch(r"[0-9]+\.[0-9]+", value):
            return value, f"is {short(value)}, expected a \"major.minor\" string such as {SCHEMA_VERSION!r}"
        return value, None
    if k in ("str", "units"):
        if not isinstance(value, str) or not value.strip():
            return value, f"is {short(value)}, expected a non-empty string"
        if k == "units" and value not in LENGTH_UNITS:
            return value, f"is {value!r}, expected one of {', '.join(LENGTH_UNITS)}"
        return value, None
    if k == "int":
        if not _is_int(value) or (spec.lo is not None and value < spec.lo) or (spec.hi is not None and value > spec.hi):
            rng = f"≥ {spec.lo}" if spec.hi is None else f"in [{spec.lo}, {spec.hi}]"
            return value, f"is {short(value)}, expected an integer {rng}"
        return int(value), None
    if k in ("float", "angle"):
        positive = (spec.group, spec.name) in POSITIVE
        ok = is_real(value) and math.isfinite(float(value))
        if ok:
            v = float(value)
            ok = (spec.lo is None or (v > spec.lo if positive else v >= spec.lo)) and (spec.hi is None or v <= spec.hi)
        if not ok:
            lo = "" if spec.lo is None else ("(" if positive else "[") + f"{spec.lo:g}"
            hi = "∞)" if spec.hi is None else f"{spec.hi:g}]"
            unit = f" {spec.units}" if spec.units else ""
            what = "an angle in radians " if k == "angle" else "a finite number "
            return value, f"is {short(value)}, expected {what}in {lo}, {hi}{unit}"
        return float(value), None
    if k == "rgb":
        arr = np.asarray(value) if isinstance(value, (list, tuple, np.ndarray)) else None
        if (arr is None or arr.shape != (3,) or arr.dtype.kind not in "iuf" or not np.all(np.isfinite(arr))
                or np.any(arr < spec.lo) or np.any(arr > spec.hi)):
            return value, f"is {short(value)}, expected 3 numbers (linear RGB) in [{spec.lo:g}, {spec.hi:g}]"
        return [float(x) for x in arr], None
    if k == "toml":
        if not isinstance(value, str):
            return value, f"is {short(value)}, expected TOML text"
        try:
            tomllib.loads(value)
        except tomllib.TOMLDecodeError as exc:
            return value, f"is not valid TOML ({' '.join(str(exc).split())})"
        return value, None
    if k == "isotime":
        try:
            datetime.datetime.fromisoformat(value)
        except (TypeError, ValueError):
            return value, f"is {short(value)}, expected an ISO 8601 time such as '2026-01-31T12:00:00+00:00'"
        return value, None
    if k.startswith("json_"):
        obj = value
        if isinstance(value, str):
            try:
                obj = json.loads(value)
            except ValueError as exc:
                return value, f"is not valid JSON ({exc})"
        elif on_disk:
            return value, f"is {short(value)}, expected JSON text"
        if not isinstance(obj, dict):
            return value, f"is {short(value)}, expected a JSON object"
        try:
            json.dumps(obj, allow_nan=False)
        except (TypeError, ValueError) as exc:
            return value, f"is not JSON-serializable ({exc})"
        if k == "json_timings" and not _json_leaves_ok(
                obj, lambda x: is_real(x) and math.isfinite(x) and x >= 0):
            return value, f"is {short(obj)}, expected an object of stage → seconds (finite, ≥ 0)"
        if k == "json_counts" and not _json_leaves_ok(obj, lambda x: _is_int(x) and x >= 0):
            return value, f"is {short(obj)}, expected an object of table → counts (integers ≥ 0, may nest)"
        return obj, None
    raise AssertionError(k)  # pragma: no cover


def encode_attr(spec: AttrSpec, value):
    """The on-disk value of a checked attribute."""
    if spec.kind.startswith("json_"):
        return json.dumps(value, sort_keys=True, allow_nan=False)
    if spec.kind == "rgb":
        return np.asarray(value, dtype=np.float64)
    if spec.kind == "int":
        return np.int64(value)
    if spec.kind in ("float", "angle"):
        return np.float64(value)
    return value


def extra_attr_problem(value):
    """Extra (non-schema) attributes in yarn/provenance/fiber_bcsdf/tables: strings, finite numbers, finite arrays."""
    value = py(value)
    if isinstance(value, str):
        return value, None
    if is_real(value) and math.isfinite(float(value)):
        return value, None
    if isinstance(value, (list, tuple, np.ndarray)):
        if all(isinstance(x, str) for x in value) and len(value) > 0:
            return list(value), None
        arr = np.asarray(value)
        if arr.dtype.kind in "iuf" and arr.ndim == 1 and np.all(np.isfinite(arr)):
            return arr, None
    return value, f"is {short(value)}, expected a string, a finite number or a 1-D finite array"


def encode_extra(value):
    """The on-disk value of a checked extra attribute (a list of strings becomes an HDF5 string array)."""
    if isinstance(value, list) and value and all(isinstance(x, str) for x in value):
        return np.array(value, dtype=h5py.string_dtype())
    return value


# --- table checks (shared by writer, reader, validator) ------------------------------------------------------------

def axis_attrs(spec: TableSpec, shape, override=None) -> dict:
    """The axis attributes the writer stores for a table of ``shape`` (override: caller's I_M axes)."""
    attrs = {}
    names = []
    for i, axis_name in enumerate(spec.axes):
        ax = AXES[axis_name]
        desc = override[i] if override is not None and ax.sampled else None
        if desc is not None:
            names.append(desc["name"])
            lo, hi = desc["range"]
            attrs[f"axis{i}_range"] = np.array([lo, hi], dtype=np.float64)
            attrs[f"axis{i}_wrap"] = desc.get("wrap", "clamp")
            attrs[f"axis{i}_units"] = desc.get("units", "1")
            attrs[f"axis{i}_definition"] = desc.get("definition", "")
            attrs[f"axis{i}_samples"] = cell_centres(float(lo), float(hi), shape[i])
            continue
        names.append(DISK_AXIS_NAME.get(axis_name, axis_name))
        if ax.sampled:
            attrs[f"axis{i}_range"] = np.array(ax.range, dtype=np.float64)
            attrs[f"axis{i}_wrap"] = ax.wrap
            attrs[f"axis{i}_units"] = ax.units
            if spec.axes_overridable:
                attrs[f"axis{i}_definition"] = ax.definition
            if ax.store_samples:
                attrs[f"axis{i}_samples"] = cell_centres(*ax.range, shape[i])
    if names:  # a scalar table (a residual) has no axes attribute
        attrs["axes"] = names
    return attrs


def table_meta_problems(name: str, spec: TableSpec, shape: tuple, dtype, attrs: dict) -> list[str]:
    """Attribute and dtype problems of one table (metadata only, no data read). ``attrs`` as plain Python."""
    probs = []
    if np.dtype(dtype) != TABLE_DTYPE:
        probs.append(f"{name}: dtype is {np.dtype(dtype)}, expected float32 (little-endian)")
    units = attrs.get("units")
    if not (isinstance(units, str) and units == spec.units):  # an array attribute compares elementwise
        probs.append(f"{name}: attr units is {'missing' if units is None else short(units)}, expected {spec.units!r}")
    est = attrs.get("error_estimate")
    if est is None:
        probs.append(f"{name}: attr error_estimate is missing, expected a finite number ≥ 0 (every table needs an "
                     f"error estimate)")
    elif not (is_real(est) and math.isfinite(float(est)) and float(est) >= 0):
        probs.append(f"{name}: attr error_estimate is {short(est)}, expected a finite number ≥ 0")
    for key in ("error_kind", "error_statistic"):
        v = attrs.get(key)
        if not isinstance(v, str) or not v.strip():
            probs.append(f"{name}: attr {key} is {'missing' if v is None else short(v)}, expected a non-empty "
                         f"string")
    if spec.mip:
        hw = attrs.get("half_width")
        if not (is_real(hw) and math.isfinite(float(hw)) and float(hw) > 0):
            probs.append(f"{name}: attr half_width is {'missing' if hw is None else short(hw)}, expected the strip "
                         f"half-width in yarn units (> 0)")
    axes = attrs.get("axes")
    ndim = len(spec.shape)
    if ndim == 0:
        return probs
    if not (isinstance(axes, list) and len(axes) == ndim and all(isinstance(a, str) and a for a in axes)):
        probs.append(f"{name}: attr axes is {short(axes)}, expected {ndim} axis names")
        return probs
    if len(shape) != ndim:
        return probs  # reported by shape_problems
    if len(set(axes)) != len(axes):
        probs.append(f"{name}: attr axes {axes} repeats a name, expected distinct axis names")
    for i, axis_name in enumerate(spec.axes):
        ax = AXES[axis_name]
        disk_name = DISK_AXIS_NAME.get(axis_name, axis_name)
        free = spec.axes_overridable and ax.sampled
        if not free and axes[i] != disk_name:
            probs.append(f"{name}: axis {i} is named {axes[i]!r}, expected {disk_name!r}")
            continue
        if not ax.sampled:
            continue
        rng = attrs.get(f"axis{i}_range")
        rng_ok = isinstance(rng, np.ndarray) and rng.shape == (2,) and rng.dtype.kind in "iuf" and bool(
            np.all(np.isfinite(rng))) and rng[0] < rng[1]
        if not rng_ok:
            probs.append(f"{name}: attr axis{i}_range is {short(rng)}, expected [lo, hi] finite with lo < hi")
            continue
        if not free and not np.allclose(rng, ax.range, rtol=0, atol=1e-12):
            probs.append(f"{name}: attr axis{i}_range is {rng.tolist()}, expected {list(ax.range)} ({axis_name})")
        wrap = attrs.get(f"axis{i}_wrap")
        expected_wrap = WRAPS if free else (ax.wrap,)
        if not (isinstance(wrap, str) and wrap in expected_wrap):
            probs.append(f"{name}: attr axis{i}_wrap is {short(wrap)}, expected "
                         f"{' or '.join(map(repr, expected_wrap))}")
        au = attrs.get(f"axis{i}_units")
        if not isinstance(au, str) or (not free and au != ax.units):
            want_units = repr(ax.units) if not free else "a string"
            probs.append(f"{name}: attr axis{i}_units is {short(au)}, expected {want_units}")
        if free:
            d = attrs.get(f"axis{i}_definition")
            if not isinstance(d, str) or not d.strip():
                probs.append(f"{name}: attr axis{i}_definition is {short(d)}, expected a non-empty description of "
                             f"the axis variable")
        samples = attrs.get(f"axis{i}_samples")
        if ax.store_samples or free:
            want = cell_centres(float(rng[0]), float(rng[1]), shape[i])
            if not (isinstance(samples, np.ndarray) and samples.shape == want.shape and samples.dtype.kind == "f"
                    and np.allclose(samples, want, rtol=1e-9, atol=1e-12)):
                probs.append(f"{name}: attr axis{i}_samples is {short(samples)}, expected the {shape[i]} cell centres "
                             f"of [{rng[0]:g}, {rng[1]:g}]")
    return probs


def _pattern_text(spec: TableSpec, level) -> str:
    parts = []
    for p in spec.shape:
        if isinstance(p, int):
            parts.append(str(p))
        elif level:
            parts.append(f"max(1, {p}>>{level})")
        else:
            parts.append(p)
    return "(" + ", ".join(parts) + ("," if len(parts) == 1 else "") + ")"


def shape_problems(entries) -> list[str]:
    """Shape problems over all tables present: ``entries`` = [(name, spec, level, shape)]. Symbols bind per family
    (mip tables: at level 0). Also checks that mip levels are contiguous from mip0."""
    probs = []
    bound = {}
    for name, spec, level, shape in sorted(entries, key=lambda e: (e[2] or 0, e[0])):
        shape = tuple(int(s) for s in shape)
        if len(shape) != len(spec.shape):
            probs.append(f"{name}: shape {shape} has {len(shape)} dimensions, expected {_pattern_text(spec, level)}")
            continue
        for dim, pat in zip(shape, spec.shape):
            if isinstance(pat, int):
                if dim != pat:
                    probs.append(f"{name}: shape {shape} does not match {_pattern_text(spec, level)}")
                    break
                continue
            if dim < 1:
                probs.append(f"{name}: shape {shape} has an empty axis {pat}, expected ≥ 1 samples")
                break
            key = (spec.family, pat)
            if key not in bound:
                if level:
                    continue  # no level 0 to bind to; the contiguity check reports it
                bound[key] = (dim, name)
                continue
            base, src = bound[key]
            want = max(1, base >> level) if level else base
            if dim != want:
                probs.append(f"{name}: shape {shape} does not match {_pattern_text(spec, level)} with {pat} = {base} "
                             f"(from {src})")
                break
    levels = {}
    for name, spec, level, _ in entries:
        if level is not None:
            levels.setdefault(spec.base, set()).add(level)
    for base, ks in sorted(levels.items()):
        if ks != set(range(max(ks) + 1)):
            missing = sorted(set(range(max(ks) + 1)) - ks)
            probs.append(f"{base}: mip levels {sorted(ks)} are not contiguous from mip0 (missing mip{missing[0]})")
    return probs


def numeric_problems(name: str, spec: TableSpec, arr: np.ndarray, what: str = "") -> list[str]:
    """Finite values, value ranges and vector lengths of a loaded float32 table."""
    label = f"{name}{what}"
    bad = ~np.isfinite(arr)
    if bad.any():
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        return [f"{label}: {int(bad.sum())} non-finite value(s) (first {arr[idx]} at index {idx}), expected finite "
                f"numbers"]
    probs = []
    tol = 1e-5

    def check_range(values, lo, hi, where):
        if values.size == 0:
            return
        if lo is not None and values.min() < lo - tol:
            probs.append(f"{label}{where}: value {float(values.min()):g} below {lo:g}, expected ≥ {lo:g}")
        if hi is not None and values.max() > hi + tol:
            probs.append(f"{label}{where}: value {float(values.max()):g} above {hi:g}, expected ≤ {hi:g}")

    check_range(arr, *spec.value_range, "")
    if spec.channel_ranges is not None:
        for c, (lo, hi) in enumerate(spec.channel_ranges):
            check_range(arr[..., c], lo, hi, f" channel {c}")
    if spec.vector:
        norm = np.sqrt(np.sum(arr[..., : spec.vector].astype(np.float64) ** 2, axis=-1))
        if norm.size and norm.max() > 1 + 1e-3:
            probs.append(f"{label}: vector length {float(norm.max()):g} above 1, expected coverage-premultiplied unit "
                         f"vectors (length ≤ 1)")
    return probs


def stderr_problems(name: str, spec: TableSpec, table_shape, err: np.ndarray, estimate) -> list[str]:
    label = f"{name}{STDERR_SUFFIX}"
    if err.dtype != TABLE_DTYPE:
        return [f"{label}: dtype is {err.dtype}, expected float32"]
    if tuple(err.shape) != tuple(table_shape):
        return [f"{label}: shape {tuple(err.shape)}, expected the table's shape {tuple(table_shape)}"]
    bad = ~np.isfinite(err)
    if bad.any():
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        return [f"{label}: {int(bad.sum())} non-finite value(s) (first at index {idx}), expected finite errors ≥ 0"]
    if err.size and err.min() < 0:
        return [f"{label}: value {float(err.min()):g} is negative, expected errors ≥ 0"]
    mx = float(err.max()) if err.size else 0.0
    if (is_real(estimate) and math.isfinite(float(estimate))
            and not math.isclose(float(estimate), mx, rel_tol=1e-6, abs_tol=1e-30)):
        return [f"{name}: attr error_estimate is {float(estimate):g}, expected the maximum of {label} ({mx:g})"]
    return []
