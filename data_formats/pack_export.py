"""Export an asset pack for other engines: textures as PNG (8-bit) and EXR (float32), tables as CSV.

* Textures (every mip level): ``<group>_mip<k>.exr`` holds the stored values; ``<group>_mip<k>.png`` maps vectors
  from [−1, 1] to [0, 255] (``(x + 1)/2``) and scalars from [0, 1]; flyaway textures give one RGBA PNG per variant
  (``flyaway_<variant>_mip<k>.png``; RGB = tangent mapped as above, A = coverage) and a 4-channel-split EXR pair.
  Rows are v (top row = first texel row), columns u, exactly the dataset layout.
* Tables: ``<group>_<name>.csv`` with one row per entry: the axis sample values (cell centres, column named after
  the axis), then the value per channel, then its standard error where the pack has one. Scalars get one row.
* ``manifest.json`` lists every file with its source dataset, shape and error estimate.
Nothing is written if the pack cannot be read; each file is written atomically.
"""

from __future__ import annotations

import csv
import itertools
import json
from pathlib import Path

import numpy as np

from .asset_pack import read_pack
from .atomic import atomic_path
from .images import write_exr


def _png(path, arr):
    from PIL import Image

    with atomic_path(path) as tmp:
        Image.fromarray(np.clip(arr * 255 + 0.5, 0, 255).astype(np.uint8)).save(tmp, format="PNG")


def _texture_files(out: Path, name: str, arr: np.ndarray) -> list[str]:
    stem = name.removeprefix("textures/").replace("/", "_")
    files = []
    if arr.ndim == 4:  # flyaway variants (3, H, W, 4)
        for k, tex in enumerate(arr):
            rgba = np.concatenate([(tex[..., :3] + 1) / 2, tex[..., 3:]], axis=-1)
            base = stem.replace("flyaway", f"flyaway_{k}")
            _png(out / f"{base}.png", rgba)
            write_exr(out / f"{base}_tangent.exr", tex[..., :3])
            write_exr(out / f"{base}_coverage.exr", np.repeat(tex[..., 3:], 3, axis=-1))
            files += [f"{base}.png", f"{base}_tangent.exr", f"{base}_coverage.exr"]
        return files
    vec = arr.ndim == 3
    _png(out / f"{stem}.png", (arr + 1) / 2 if vec else arr)
    write_exr(out / f"{stem}.exr", arr if vec else np.repeat(arr[..., None], 3, axis=-1))
    return [f"{stem}.png", f"{stem}.exr"]


def _table_csv(out: Path, name: str, arr: np.ndarray, err, info) -> str:
    file = name.replace("/", "_") + ".csv"
    grid_axes = [a for a in info.axes if a.name != "channel"]
    has_channel = bool(info.axes) and info.axes[-1].name == "channel"
    with atomic_path(out / file) as tmp, open(tmp, "w", newline="") as fh:
        writer = csv.writer(fh)
        channels = ["r", "g", "b"] if has_channel else ["value"]
        header = [a.name for a in grid_axes] + channels + ([f"{c}_stderr" for c in channels] if err is not None else [])
        writer.writerow(header)
        value_shape = arr.shape[:-1] if has_channel else arr.shape
        samples = [a.samples if a.samples is not None else np.arange(a.size) for a in grid_axes]
        for index in itertools.product(*(range(n) for n in value_shape)):
            vals = np.atleast_1d(arr[index]).tolist()
            row = [float(samples[i][j]) for i, j in enumerate(index)] + vals
            if err is not None:
                row += np.atleast_1d(err[index]).tolist()
            writer.writerow(row)
    return file


def export_pack(pack_path, out_dir) -> dict:
    """Write every table of the pack into ``out_dir`` (created if missing); returns the manifest."""
    pack = read_pack(pack_path, tables=None)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    manifest = {"pack": str(pack_path), "yarn": pack.yarn, "files": []}
    for name, arr in sorted(pack.tables.items()):
        info = pack.info[name]
        if name.startswith("textures/"):
            files = _texture_files(out, name, np.asarray(arr, np.float32))
        else:
            files = [_table_csv(out, name, np.asarray(arr), pack.stderr.get(name), info)]
        manifest["files"].append({"dataset": name, "shape": list(np.shape(arr)), "files": files,
                                  "error_estimate": info.error_estimate})
    with atomic_path(out / "manifest.json") as tmp:
        Path(tmp).write_text(json.dumps(manifest, indent=2))
    return manifest
