"""Asset-pack reader: ``read_pack`` (lazy: every table's metadata, the data of the tables asked for),
``validate`` (every problem, one line each), ``sniff`` and ``describe`` (the summary ``knitbake inspect`` prints)."""

from __future__ import annotations


import h5py
import numpy as np

from ..errors import FormatError
from ..input_files import HDF5_MAGIC, open_hdf5, read_head
from ..jsonable import jsonable
from .checks import (attr_problem, is_real, numeric_problems, py, raise_problems, shape_problems, short,
                     stderr_problems, table_meta_problems)
from .pack import AssetPack, AxisInfo, TableInfo
from .schema import (ATTRS, AXES, FORMAT_NAME, GROUPS, SCHEMA_MAJOR, SCHEMA_MINOR, SCHEMA_VERSION, STDERR_SUFFIX,
                     TABLE_DTYPE, TABLES, known_names_hint, resolve_table)


def _version(f, path, probs):
    """(major, minor) of an open pack, or None after recording why the file is not readable as a pack."""
    fmt = py(f.attrs.get("format"))
    if not (isinstance(fmt, str) and fmt == FORMAT_NAME):  # an array attribute compares elementwise
        probs.append(f"root attr format is {'missing' if fmt is None else short(fmt)}, expected {FORMAT_NAME!r}")
        return None
    spec = next(a for a in ATTRS if a.name == "schema_version")
    raw = f.attrs.get("schema_version")
    if raw is None:
        probs.append(f"root attr schema_version is missing, expected {SCHEMA_VERSION!r}")
        return None
    value, prob = attr_problem(spec, raw, on_disk=True)
    if prob:
        probs.append(f"root attr schema_version {prob}")
        return None
    major, minor = (int(p) for p in value.split("."))
    if major != SCHEMA_MAJOR:
        probs.append(f"schema_version {value!r} has unknown major version {major}; this reader supports "
                     f"{SCHEMA_MAJOR}.x (up to {SCHEMA_VERSION})")
        return None
    return major, minor


def _read_groups(f, probs) -> dict:
    out = {}
    for group in GROUPS:
        node = f.get(group)
        if not isinstance(node, h5py.Group):
            probs.append(f"group /{group} is missing, expected a group with attrs "
                         f"{', '.join(a.name for a in ATTRS if a.group == group)}")
            out[group] = {}
            continue
        attrs = dict(node.attrs.items())  # items(): a third faster than reading key by key in h5py 3
        values = {}
        for spec in ATTRS:
            if spec.group != group:
                continue
            if spec.name not in attrs:
                probs.append(f"{group}.{spec.name} is missing, expected {spec.description}")
                continue
            value, prob = attr_problem(spec, attrs.pop(spec.name), on_disk=True)
            if prob:
                probs.append(f"{group}.{spec.name} {prob}")
            values[spec.name] = value
        for key, value in attrs.items():
            values[key] = py(value)
        out[group] = values
    return out


def _scan(f, strict: bool, probs) -> dict:
    """Every dataset in the file, classified: name -> (spec, level, h5py.Dataset, stderr Dataset or None).
    Unknown members are problems when ``strict`` (a file of our minor version or older)."""
    found = {}
    datasets = {}
    others = []

    def visit(name, obj):
        if isinstance(obj, h5py.Dataset):
            datasets[name] = obj
        elif name not in GROUPS and not any(t.name.startswith(name + "/") for t in TABLES):
            others.append(name)

    f.visititems(visit)
    for name, ds in datasets.items():
        if name.endswith(STDERR_SUFFIX) and resolve_table(name[: -len(STDERR_SUFFIX)]):
            continue
        resolved = resolve_table(name)
        if resolved is None:
            if strict:
                probs.append(f"{name}: unknown dataset (not in schema {SCHEMA_VERSION})")
            continue
        stderr = datasets.get(name + STDERR_SUFFIX)
        found[name] = (*resolved, ds, stderr)
    for name, ds in datasets.items():
        if name.endswith(STDERR_SUFFIX) and resolve_table(name[: -len(STDERR_SUFFIX)]):
            if name[: -len(STDERR_SUFFIX)] not in found:
                probs.append(f"{name}: per-entry errors for a table that is not in the pack")
    if strict:
        for name in others:
            if resolve_table(name) is not None:
                probs.append(f"{name}: is a group, expected a dataset")
            else:
                probs.append(f"{name}: unknown group (not in schema {SCHEMA_VERSION})")
    return found


def _table_info(name, spec, ds, stderr_ds, probs) -> TableInfo:
    attrs = {k: py(v) for k, v in ds.attrs.items()}  # items(): as in _read_groups
    probs.extend(table_meta_problems(name, spec, ds.shape, ds.dtype, attrs))
    axes = []
    names = attrs.get("axes") if isinstance(attrs.get("axes"), list) else []
    for i, dim in enumerate(ds.shape):
        rng = attrs.get(f"axis{i}_range")
        rng = (float(rng[0]), float(rng[1])) if isinstance(rng, np.ndarray) and rng.shape == (2,) else None
        axes.append(AxisInfo(name=names[i] if i < len(names) else f"axis{i}", size=int(dim), range=rng,
                             wrap=attrs.get(f"axis{i}_wrap"), units=attrs.get(f"axis{i}_units", ""),
                             definition=attrs.get(f"axis{i}_definition",
                                                  AXES[spec.axes[i]].definition if i < len(spec.axes) else "")))
    est = attrs.get("error_estimate")
    return TableInfo(name=name, shape=tuple(int(s) for s in ds.shape), units=attrs.get("units", ""), axes=axes,
                     error_estimate=float(est) if is_real(est) else float("nan"),
                     error_kind=str(attrs.get("error_kind", "")), error_statistic=str(attrs.get("error_statistic", "")),
                     has_stderr=stderr_ds is not None, attrs=attrs)


def _load(name, spec, ds, stderr_ds, info, probs):
    data = ds[()]
    data = np.asarray(data)
    probs.extend(numeric_problems(name, spec, data.astype(TABLE_DTYPE, copy=False)
                                   if data.dtype.kind == "f" else data.astype(np.float64)))
    err = None
    if stderr_ds is not None:
        err = np.asarray(stderr_ds[()])
        probs.extend(stderr_problems(name, spec, data.shape, err, info.error_estimate))
    return data, err


def _open(path):
    return open_hdf5(path, "an asset pack (.h5)")


def _read(path, tables, probs):
    """The reading core shared by read_pack (probs raise) and validate (probs are returned)."""
    f = _open(path)
    with f:
        ver = _version(f, path, probs)
        if ver is None:
            return None
        strict = ver[1] <= SCHEMA_MINOR
        groups = _read_groups(f, probs)
        found = _scan(f, strict, probs)
        probs.extend(shape_problems([(n, s, lvl, ds.shape) for n, (s, lvl, ds, _) in found.items()]))
        info = {n: _table_info(n, s, ds, e, probs) for n, (s, lvl, ds, e) in found.items()}
        if tables is None:
            wanted = list(found)
        else:
            wanted = []
            for name in tables:
                if resolve_table(name) is None:
                    probs.append(f"table {name!r} is not in the schema (known: {known_names_hint()})")
                elif name not in found:
                    probs.append(f"table {name!r} is not in this pack (present: {', '.join(found) or 'none'})")
                else:
                    wanted.append(name)
        loaded, stderr = {}, {}
        for name in wanted:
            spec, level, ds, e = found[name]
            try:
                data, err = _load(name, spec, ds, e, info[name], probs)
            except (OSError, ValueError, TypeError) as exc:
                probs.append(f"{name}: cannot read data ({' '.join(str(exc).split())})")
                continue
            loaded[name] = data
            if err is not None:
                stderr[name] = err
        return AssetPack(path=str(path), schema_version=str(py(f.attrs["schema_version"])),
                         yarn=groups["yarn"], provenance=groups["provenance"], fiber_bcsdf=groups["fiber_bcsdf"],
                         info=info, tables=loaded, stderr=stderr)


def read_pack(path, tables: list | None = None) -> AssetPack:
    """Read a pack: all attribute groups and every table's metadata, but the data of only ``tables`` (None: all).
    Raises FormatError (one line) on any problem with what it read."""
    probs = []
    try:
        pack = _read(path, None if tables is None else list(tables), probs)
    except (OSError, KeyError, RuntimeError) as exc:
        raise FormatError(f"{path}: unreadable asset pack ({' '.join(str(exc).split())})") from None
    raise_problems(path, probs)
    return pack


def validate(path) -> list[str]:
    """Every schema and numeric problem of a pack, one line each (empty: valid). Never raises."""
    probs = []
    try:
        _read(path, None, probs)
    except FormatError as exc:
        return [str(exc)]
    except Exception as exc:  # noqa: BLE001 — validate reports corrupt content, whatever the library raised
        probs.append(f"unreadable content ({exc.__class__.__name__}: {' '.join(str(exc).split())})")
    return [f"{path}: {p}" for p in probs]


def sniff(path) -> bool:
    """True if ``path`` is an HDF5 file whose root attr ``format`` is "knit-asset-pack". Never raises."""
    if read_head(path, 8) != HDF5_MAGIC:
        return False
    try:
        with h5py.File(path, "r") as f:
            fmt = py(f.attrs.get("format"))
            return isinstance(fmt, str) and fmt == FORMAT_NAME
    except Exception:  # noqa: BLE001
        return False


def describe(path) -> dict:
    """JSON-serializable summary for ``knitbake inspect``: kind, yarn, provenance, BCSDF, and every table with its
    shape, units, axes and error estimate. Reads no table data. Raises FormatError for a bad pack."""
    pack = read_pack(path, tables=[])
    out = {"kind": "asset-pack", "path": str(path), "format": FORMAT_NAME, "schema_version": pack.schema_version,
           "yarn": pack.yarn, "provenance": pack.provenance, "fiber_bcsdf": pack.fiber_bcsdf, "tables": {}}
    for name, info in sorted(pack.info.items()):
        out["tables"][name] = {
            "shape": list(info.shape), "units": info.units,
            "axes": [{"name": a.name, "size": a.size,
                      **({"range": list(a.range), "wrap": a.wrap, "units": a.units, "definition": a.definition}
                         if a.range else {})} for a in info.axes],
            "error_estimate": info.error_estimate, "error_kind": info.error_kind,
            "error_statistic": info.error_statistic, "per_entry_errors": info.has_stderr,
            **({"notes": notes} if (notes := _extra_attrs(info.attrs)) else {})}
    return jsonable(out)


_STANDARD_ATTRS = {"units", "description", "error_estimate", "error_kind", "error_statistic", "axes", "half_width",
                   "error_of"}


def _extra_attrs(attrs: dict) -> dict:
    """A table's attributes beyond those §4.1 defines (a baker's extra figures, e.g. the I_M lookup error)."""
    return {k: v for k, v in attrs.items() if k not in _STANDARD_ATTRS and not k.startswith("axis")}
