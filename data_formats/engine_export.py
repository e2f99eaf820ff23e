"""Engine-ready export of an asset pack: every table as a raw little-endian ``.bin`` and a ``manifest.json`` that
says how to read and look it up, validated by a JSON Schema shipped with the package
(``schemas/engine_export.schema.json``, in the glTF-Validator spirit). ASSET_PACK.md §14 documents it field by field.

* One file per dataset, ``<dataset with '/' as '_'>.bin``: the values in the dataset's row-major order (C order,
  last axis fastest), as ``float32`` (default; exact) or ``float16`` (half the bytes; IEEE rounding to nearest, a
  relative error ≤ 2^−11 for normal values; values beyond ±65504 are refused, never written as infinity).
* RGBA where engines need it: a table whose last axis is 3 colour channels is written with 4 (A = 0), because GPU
  APIs offer RGBA32F/RGBA16F storage everywhere and RGB32F not (Vulkan, WebGPU); the manifest's ``padded_from`` = 3
  says so. Scalar textures (AO, coverage) stay one channel (R32F/R16F); flyaway textures are RGBA already.
* ``manifest.json``: format ``knit-engine-export`` 1.0, the pack's yarn and fiber BCSDF attributes, and per table
  its file, dtype, byte order, byte length, shape as written and as stored in the pack, its axes (name, size, and
  for sampled axes the range [lo, hi] of the cell-centred samples, wrap and units), units, value range, error
  estimate and the lookup rule (multilinear over the sampled axes with per-axis wrap, ASSET_PACK.md §4.3).
* ``read_export(folder)`` reads the tables back from the ``.bin`` files and the manifest alone (what an engine
  does); ``validate_export(folder)`` lists every problem (schema, missing or mis-sized files, non-finite values).
Nothing is written when the pack cannot be read; every file is written atomically.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .asset_pack import read_pack
from .atomic import atomic_path
from .errors import FormatError
from .input_files import regular_file

FORMAT = "knit-engine-export"
VERSION = "1.0"
DTYPES = {"float32": np.dtype("<f4"), "float16": np.dtype("<f2")}
LOOKUP = ("multilinear over the sampled axes (cell-centred samples over range, per-axis wrap); index axes "
          "(channel, variant) are selected, never interpolated: ASSET_PACK.md §4.3")
SCHEMA_PATH = Path(__file__).with_name("schemas") / "engine_export.schema.json"


def _file_name(dataset: str) -> str:
    return dataset.replace("/", "_") + ".bin"


def _as_written(arr: np.ndarray, axes) -> tuple[np.ndarray, int | None]:
    """(values to write, padded_from): RGB tables padded to RGBA with A = 0."""
    if axes and axes[-1].name == "channel" and arr.shape[-1] == 3:
        return np.concatenate([arr, np.zeros(arr.shape[:-1] + (1,), arr.dtype)], axis=-1), 3
    return arr, None


def _axis_entry(axis) -> dict:
    entry = {"name": axis.name, "size": int(axis.size)}
    if axis.range is not None:
        entry.update(range=[float(axis.range[0]), float(axis.range[1])], wrap=axis.wrap, units=axis.units)
        if axis.definition:
            entry["definition"] = axis.definition
    return entry


def schema() -> dict:
    return json.loads(SCHEMA_PATH.read_text())


def _schema_problems(manifest: dict) -> list[str]:
    import jsonschema

    validator = jsonschema.Draft202012Validator(schema())
    return [f"manifest.json: {'/'.join(map(str, e.absolute_path)) or '(root)'}: {e.message}"
            for e in sorted(validator.iter_errors(manifest), key=lambda e: list(map(str, e.absolute_path)))]


def export_engine(pack_path, out_dir, dtype: str = "float32") -> dict:
    """Write every table of the pack as ``.bin`` into ``out_dir`` (created if missing) with ``manifest.json``;
    returns the manifest. FormatError (one line) for a bad pack or a value float16 cannot hold, before any file."""
    if dtype not in DTYPES:
        raise FormatError(f"dtype {dtype!r}: expected one of {', '.join(DTYPES)}")
    pack = read_pack(pack_path, tables=None)
    target = DTYPES[dtype]
    tables, payloads = [], {}
    for name, arr in sorted(pack.tables.items()):
        info = pack.info[name]
        values, padded_from = _as_written(np.asarray(arr, np.float64), info.axes)
        if dtype == "float16" and values.size and np.abs(values).max() > np.finfo(np.float16).max:
            raise FormatError(f"{pack_path}: {name} holds {np.abs(values).max():g}, beyond float16's 65504: "
                              f"export it as float32")
        data = np.array(values, dtype=target, order="C")  # (ascontiguousarray would make a scalar 1-D)
        file = _file_name(name)
        payloads[file] = data
        tables.append({
            "dataset": name, "file": file, "dtype": dtype, "byte_order": "little", "byte_length": int(data.nbytes),
            "shape": list(data.shape), "source_shape": list(np.shape(arr)), "padded_from": padded_from,
            "axes": [_axis_entry(a) for a in info.axes], "units": info.units,
            "value_range": [float(values.min()), float(values.max())] if values.size else [0.0, 0.0],
            "error_estimate": float(info.error_estimate), "lookup": LOOKUP})
    manifest = {"format": FORMAT, "version": VERSION, "pack": Path(pack_path).name, "yarn": pack.yarn,
                "fiber_bcsdf": pack.fiber_bcsdf, "tables": tables}
    manifest = json.loads(json.dumps(manifest, default=_plain))
    problems = _schema_problems(manifest)
    if problems:  # our own writer broke the schema: a bug, not the user's input
        raise RuntimeError(f"engine export: the manifest breaks its schema: {problems[0]}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for file, data in payloads.items():
        with atomic_path(out / file) as tmp:
            data.tofile(tmp)
    with atomic_path(out / "manifest.json") as tmp:
        Path(tmp).write_text(json.dumps(manifest, indent=2))
    return manifest


def _plain(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON: {type(value).__name__}")


def _manifest(folder) -> dict:
    path = Path(folder) / "manifest.json" if Path(folder).is_dir() else Path(folder)
    regular_file(path, "an engine-export manifest")
    try:
        manifest = json.loads(path.read_text())
    except (UnicodeDecodeError, ValueError) as e:
        raise FormatError(f"{path}: not JSON ({' '.join(str(e).split())})") from None
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        raise FormatError(f"{path}: not a {FORMAT} manifest (its format is "
                          f"{manifest.get('format') if isinstance(manifest, dict) else type(manifest).__name__!r})")
    return manifest


def validate_export(folder) -> list[str]:
    """Every problem of an export folder (or its manifest.json), one line each; empty when valid. Never raises."""
    try:
        manifest = _manifest(folder)
    except FormatError as e:
        return [str(e)]
    problems = _schema_problems(manifest)
    if problems:
        return problems
    root = Path(folder) if Path(folder).is_dir() else Path(folder).parent
    for table in manifest["tables"]:
        path = root / table["file"]
        want = int(np.prod(table["shape"], dtype=np.int64)) * DTYPES[table["dtype"]].itemsize
        if table["byte_length"] != want:
            problems.append(f"{table['file']}: byte_length {table['byte_length']}, shape {table['shape']} of "
                            f"{table['dtype']} needs {want}")
        elif not path.is_file() or path.stat().st_size != want:
            problems.append(f"{table['file']}: {'missing' if not path.is_file() else f'{path.stat().st_size} bytes'}"
                            f", expected {want}")
        elif not np.all(np.isfinite(np.fromfile(path, DTYPES[table["dtype"]]))):
            problems.append(f"{table['file']}: holds non-finite values")
    return problems


def read_export(folder) -> dict:
    """{dataset: array} read from the ``.bin`` files and the manifest alone, with the RGBA padding removed (the
    pack's shapes), as float32 or float16. FormatError (one line) on any problem ``validate_export`` finds."""
    problems = validate_export(folder)
    if problems:
        more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
        raise FormatError(f"{folder}: {problems[0]}{more}")
    manifest = _manifest(folder)
    root = Path(folder) if Path(folder).is_dir() else Path(folder).parent
    out = {}
    for table in manifest["tables"]:
        data = np.fromfile(root / table["file"], DTYPES[table["dtype"]]).reshape(table["shape"])
        out[table["dataset"]] = data[..., :table["padded_from"]] if table["padded_from"] else data
    return out


def sniff(path) -> bool:
    """True for a JSON file whose ``format`` is ``knit-engine-export`` (a manifest). Never raises."""
    from .input_files import read_head

    if read_head(path, 1) != b"{":
        return False
    try:
        _manifest(path)
    except Exception:  # noqa: BLE001
        return False
    return True


def describe(path) -> dict:
    """Summary of an export for ``knitbake inspect``: yarn, tables (dtype, shape, file) and total bytes."""
    manifest = _manifest(path)
    return {"kind": "engine-export", "format": FORMAT, "version": manifest.get("version"),
            "yarn": manifest.get("yarn"), "tables": {t.get("dataset"): {"file": t.get("file"), "dtype": t.get("dtype"),
                                                                         "shape": t.get("shape")}
                                                     for t in manifest.get("tables", []) if isinstance(t, dict)}}


validate = validate_export
