"""Asset-pack writer: ``write_pack`` checks every group, table, error estimate and axis description through the
shared checks before it creates the file, then writes it atomically."""

from __future__ import annotations

import datetime
import math
from pathlib import Path

import h5py
import numpy as np

from ..atomic import atomic_path
from ..errors import FormatError
from .checks import (attr_problem, axis_attrs, encode_attr, encode_extra, extra_attr_problem, is_real,
                     numeric_problems, raise_problems, shape_problems, short, stderr_problems, table_meta_problems)
from .schema import (ATTRS, AXES, COMPRESS_BYTES, DEFAULT_ERROR_KIND, FORMAT_NAME, SCHEMA_VERSION, STDERR_SUFFIX,
                     TABLE_DTYPE, known_names_hint, resolve_table)


# attributes a writer may not set through table_attrs (the writer owns them)
_RESERVED_TABLE_ATTRS = {"units", "error_estimate", "axes", "description", "error_of"}


def _check_group_input(path, group: str, given: dict) -> dict:
    """Check the writer's dict for one attribute group; returns name → on-disk value."""
    if not isinstance(given, dict):
        raise FormatError(f"{path}: {group} must be a dict, got {type(given).__name__}")
    given = dict(given)
    if group == "provenance" and "created" not in given:
        given["created"] = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    out = {}
    for spec in ATTRS:
        if spec.group != group:
            continue
        if spec.name not in given:
            raise FormatError(f"{path}: {group}.{spec.name} is missing, expected {spec.description}")
        value, prob = attr_problem(spec, given.pop(spec.name), on_disk=False)
        if prob:
            raise FormatError(f"{path}: {group}.{spec.name} {prob}")
        out[spec.name] = encode_attr(spec, value)
    for key, value in given.items():
        value, prob = extra_attr_problem(value)
        if prob or not isinstance(key, str) or not key:
            raise FormatError(f"{path}: {group}.{key} {prob or 'has an invalid name'}")
        out[key] = encode_extra(value)
    return out


def _check_axes_override(path, name, spec, axes) -> dict:
    sampled = [i for i, a in enumerate(spec.axes) if AXES[a].sampled]
    if not isinstance(axes, (list, tuple)) or len(axes) != len(sampled):
        raise FormatError(f"{path}: table_attrs[{name!r}]['axes'] is {short(axes)}, expected a list of "
                          f"{len(sampled)} dicts with name, range, wrap, units, definition")
    override = {}
    for i, desc in zip(sampled, axes):
        if not isinstance(desc, dict) or not {"name", "range", "definition"} <= set(desc) or not set(desc) <= {
                "name", "range", "wrap", "units", "definition"}:
            raise FormatError(f"{path}: table_attrs[{name!r}]['axes'][{i}] is {short(desc)}, expected a dict with "
                              f"name, range, definition and optionally wrap, units")
        override[i] = desc
    return override


def write_pack(path, yarn: dict, provenance: dict, fiber_bcsdf: dict, tables: dict, errors: dict,
               table_attrs: dict | None = None) -> None:
    """Write an asset pack atomically. Everything is checked before the file is created; a FormatError names the
    bad member. ``tables``: name → array (any real float dtype, stored float32); ``errors``: name → scalar error
    estimate or same-shape per-entry standard errors (stored as ``<name>_stderr``, ``error_estimate`` = their
    maximum); ``table_attrs``: name → {error_kind, error_statistic, half_width (textures), axes (I_M), extra}."""
    path = Path(path)
    groups = {g: _check_group_input(path, g, d) for g, d in
              (("yarn", yarn), ("provenance", provenance), ("fiber_bcsdf", fiber_bcsdf))}
    tables = dict(tables or {})
    errors = dict(errors or {})
    table_attrs = dict(table_attrs or {})
    for key in errors:
        if key not in tables:
            raise FormatError(f"{path}: errors[{key!r}] is given for a table that is not written")
    for key in table_attrs:
        if key not in tables:
            raise FormatError(f"{path}: table_attrs[{key!r}] is given for a table that is not written")

    planned = {}  # name -> (spec, level, data, stderr or None, attrs)
    entries = []
    for name, value in tables.items():
        resolved = resolve_table(name) if isinstance(name, str) else None
        if resolved is None:
            raise FormatError(f"{path}: table {name!r} is not in the schema (known: {known_names_hint()})")
        spec, level = resolved
        arr = np.asarray(value)
        if arr.dtype.kind != "f":
            raise FormatError(f"{path}: {name}: dtype is {arr.dtype}, expected a real floating-point array "
                              f"(stored as float32)")
        with np.errstate(over="ignore", invalid="ignore"):
            data = np.array(arr, dtype=TABLE_DTYPE, order="C")
        entries.append((name, spec, level, data.shape))
        raise_problems(path, shape_problems([(name, spec, None, data.shape)]))  # rank and fixed dimensions
        if np.all(np.isfinite(arr)) and not np.all(np.isfinite(data)):
            raise FormatError(f"{path}: {name}: values overflow float32 (max |x| = {float(np.abs(arr).max()):g}), "
                              f"expected |x| < 3.4e38")
        raise_problems(path, numeric_problems(name, spec, data))
        if name not in errors:
            raise FormatError(f"{path}: {name}: no error estimate (errors[{name!r}] is missing; every table needs "
                              f"a scalar or per-entry error)")
        err = errors[name]
        stderr = None
        extra = dict(table_attrs.get(name) or {})
        if np.ndim(err) == 0:
            if not is_real(err) or not math.isfinite(float(err)) or float(err) < 0:
                raise FormatError(f"{path}: errors[{name!r}] is {short(err)}, expected a finite number ≥ 0")
            estimate = float(err)
            statistic = extra.pop("error_statistic", "max")
        else:
            e = np.asarray(err)
            if e.dtype.kind not in "f":
                raise FormatError(f"{path}: errors[{name!r}] dtype is {e.dtype}, expected floats")
            with np.errstate(over="ignore", invalid="ignore"):
                stderr = np.array(e, dtype=TABLE_DTYPE, order="C")
            raise_problems(path, stderr_problems(name, spec, data.shape, stderr, None))
            estimate = float(stderr.max()) if stderr.size else 0.0
            if extra.pop("error_statistic", "max") != "max":
                raise FormatError(f"{path}: table_attrs[{name!r}]['error_statistic'] must be 'max' when per-entry "
                                  f"errors are given (error_estimate is their maximum)")
            statistic = "max"
        kind = extra.pop("error_kind", DEFAULT_ERROR_KIND)
        override = None
        if "axes" in extra:
            if not spec.axes_overridable:
                raise FormatError(f"{path}: table_attrs[{name!r}]['axes']: the axes of {name} are fixed by the schema")
            override = _check_axes_override(path, name, spec, extra.pop("axes"))
        attrs = {"units": spec.units, "description": spec.description, "error_estimate": estimate,
                 "error_kind": kind, "error_statistic": statistic}
        if spec.mip:
            attrs["half_width"] = extra.pop("half_width", None)
            if attrs["half_width"] is None:
                if spec.family == "flyaway":
                    raise FormatError(f"{path}: {name}: table_attrs[{name!r}]['half_width'] is missing, expected "
                                      f"the flyaway strip half-width in yarn units (flyaways reach past the radius)")
                attrs["half_width"] = groups["yarn"]["radius"]
        elif "half_width" in extra:
            raise FormatError(f"{path}: table_attrs[{name!r}]['half_width']: only texture tables have a half_width")
        for key, value in extra.items():
            if key in _RESERVED_TABLE_ATTRS or not isinstance(key, str) or key.startswith("axis"):
                raise FormatError(f"{path}: table_attrs[{name!r}][{key!r}] is reserved (set by the writer)")
            value, prob = extra_attr_problem(value)
            if prob:
                raise FormatError(f"{path}: table_attrs[{name!r}][{key!r}] {prob}")
            attrs[key] = value
        if len(data.shape) == len(spec.shape):
            try:
                attrs.update(axis_attrs(spec, data.shape, override))
            except (TypeError, ValueError) as exc:
                raise FormatError(f"{path}: table_attrs[{name!r}]['axes'] is malformed ({exc})") from None
        planned[name] = (spec, level, data, stderr, attrs)

    raise_problems(path, shape_problems(entries))
    for name, (spec, level, data, stderr, attrs) in planned.items():
        raise_problems(path, table_meta_problems(name, spec, data.shape, data.dtype, attrs))

    with atomic_path(path) as tmp:
        with h5py.File(tmp, "w") as f:
            f.attrs["format"] = FORMAT_NAME
            f.attrs["schema_version"] = SCHEMA_VERSION
            for group, attrs in groups.items():
                g = f.create_group(group)
                for key, value in attrs.items():
                    g.attrs[key] = value
            for name, (spec, level, data, stderr, attrs) in planned.items():
                _write_dataset(f, name, data, attrs)
                if stderr is not None:
                    _write_dataset(f, name + STDERR_SUFFIX, stderr, {"units": spec.units, "error_of": name})


def _write_dataset(f, name, data, attrs):
    kw = {}
    if data.nbytes >= COMPRESS_BYTES:
        kw = {"compression": "gzip", "compression_opts": 4, "shuffle": True}
    ds = f.create_dataset(name, data=data, **kw)
    for key, value in attrs.items():
        ds.attrs[key] = encode_extra(value)
