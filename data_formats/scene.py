"""Scene file (TOML, ``format = "knit-scene"``, version 1.0): yarns, camera, lights, background, render settings.

Conventions (the full spec is ``SCENE.md``)
-------------------------------------------
* Lengths are in the scene's ``units`` (``mm``, ``cm`` or ``m``); angles in degrees; colours and light strengths
  are linear RGB triples.
* Relative paths are relative to the folder of the scene file; ``load_scene`` resolves them to absolute paths and
  ``dumps_scene`` writes them relative to the folder of the file being written.
* A ``[[yarns]]`` entry draws the curves of one source — ``curves`` (knit-yarn-curves HDF5 or BCC) or
  ``stitch_mesh`` (the knot simulator's input; only its existence is checked) — with one yarn: every yarn type of
  the source, or only ``yarn_type`` (a name from the file's ``yarn_types`` or a 0-based index). Several entries may
  share a curve file with different ``yarn_type``; each yarn type of a curve file is drawn by exactly one entry.
* ``yarn`` is a preset name, or a yarn-spec file when it ends in ``.toml``.
* Every error is a ``FormatError`` with one line naming the file, the field (``camera.fov_deg``,
  ``yarns[1].radius``), the value and what is allowed.
"""

from __future__ import annotations

import dataclasses
import math
import os
import sys
from pathlib import Path

import tomli_w

from . import bcc, yarn_curves
from .atomic import atomic_path
from .conventions import CM_PER_UNIT, LENGTH_UNITS, MAX_COORD
from .errors import FormatError
from .input_files import open_hdf5, read_head, regular_file
from .yarn_spec import YarnSpec, load_preset, load_spec, preset_names

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

FORMAT_NAME = "knit-scene"
FORMAT_VERSION = "1.0"
LIGHT_TYPES = ("directional", "environment")
BUILTIN_ENVIRONMENTS = ("sky",)
MSAA_LEVELS = (1, 2, 4, 8, 16)
MAX_IMAGE_SIZE = 16384
MAX_RGB = 1e6  # irradiance, environment scale and background upper bound
# [render] key: (default, lo, hi, meaning); msaa must be in MSAA_LEVELS, shadow_map_size a power of two.
RENDER_FIELDS = {
    "spp": (64, 1, 1_000_000, "samples per pixel of the reference path tracer"),
    "max_depth": (32, 1, 1000, "longest light path (scattering events) of the reference path tracer"),
    "seed": (0, 0, 2**63 - 1, "random seed of fiber generation and path tracing"),
    "msaa": (4, 1, 16, "samples per pixel of the strip renderer's rasteriser (1, 2, 4, 8 or 16)"),
    # the fit's cost grows ~J^1.5 (1.6 s at 16, 6 s at 32, 12.7 s at 64 on the built-in sky, 2 cores: BENCHMARKS,
    # "Hostile inputs"; > 240 s at 256) and every lobe adds a shadow map, so J stops at 64
    "srbf_count": (16, 1, 64, "J, spherical Gaussians fitted to an environment light"),
    "shadow_map_size": (2048, 64, 16384, "yarn-level shadow-map resolution (a power of two)"),
    "frame": (0, 0, 2**31 - 1, "frame of the yarn curves to draw (0-based)"),
    "layers": (2, 1, 2, "layers of regular strips the strip renderer composites per sample (2: the yarn behind a "
                        "strip shows through its partial coverage; both backends)"),
    "hair_layers": (3, 1, 8, "flyaway strips the strip renderer composites per sample, the nearest first (3: the "
                             "hairs of three yarns where their strips overlap; both backends)"),
}


@dataclasses.dataclass(frozen=True)
class YarnEntry:
    """One ``[[yarns]]`` entry; paths absolute. ``yarn`` is a preset name or an absolute spec path; ``spec`` the
    loaded yarn; ``radius`` in scene units; ``yarn_type_indices`` the yarn types of the curve file it draws
    (empty for a stitch mesh)."""

    curves: Path | None
    stitch_mesh: Path | None
    yarn_type: str | int | None
    yarn: str
    spec: YarnSpec
    radius: float
    pack: Path | None
    color: tuple
    yarn_type_indices: tuple


@dataclasses.dataclass(frozen=True)
class Camera:
    """Pinhole (``fov_deg``: vertical field of view) or orthographic (``ortho_height``: visible height) camera."""

    position: tuple
    look_at: tuple
    up: tuple
    fov_deg: float | None
    ortho_height: float | None
    width: int
    height: int


@dataclasses.dataclass(frozen=True)
class DirectionalLight:
    """``direction`` toward the light as written (non-zero, any length; ``unit_direction`` normalises it);
    ``irradiance`` on a surface facing the light (RGB)."""

    direction: tuple
    irradiance: tuple

    @property
    def unit_direction(self) -> tuple:
        n = math.hypot(*self.direction)
        return tuple(x / n for x in self.direction)


@dataclasses.dataclass(frozen=True)
class EnvironmentLight:
    """Equirectangular HDR ``file`` or a ``builtin`` analytic environment, times ``scale`` (RGB)."""

    file: Path | None
    builtin: str | None
    scale: tuple


@dataclasses.dataclass(frozen=True)
class RenderSettings:
    spp: int
    max_depth: int
    seed: int
    msaa: int
    srbf_count: int
    shadow_map_size: int
    frame: int
    layers: int
    hair_layers: int


@dataclasses.dataclass(frozen=True)
class Scene:
    units: str
    yarns: tuple
    camera: Camera
    lights: tuple
    background: tuple
    render: RenderSettings
    name: str = ""
    description: str = ""


# --- field checks ---------------------------------------------------------------------------------------------------

def _number(value, where, lo, hi, lo_open=False, hi_open=False, unit=""):
    interval = f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}{' ' + unit if unit else ''}"
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise FormatError(f"{where} = {value!r} is not a number (allowed {interval})")
    v = float(value)
    if not math.isfinite(v):
        raise FormatError(f"{where} = {value!r} is not finite (allowed {interval})")
    if v < lo or v > hi or (lo_open and v == lo) or (hi_open and v == hi):
        raise FormatError(f"{where} = {value!r} is out of range (allowed {interval})")
    return v


def _integer(value, where, lo, hi):
    if isinstance(value, bool) or not isinstance(value, int):
        raise FormatError(f"{where} = {value!r} must be an integer in [{lo}, {hi}]")
    if not lo <= value <= hi:
        raise FormatError(f"{where} = {value!r} is out of range (allowed integers [{lo}, {hi}])")
    return value


def _triple(value, where, lo=-MAX_COORD, hi=MAX_COORD, what=f"numbers in [{-MAX_COORD:g}, {MAX_COORD:g}]"):
    if not isinstance(value, list) or len(value) != 3:
        raise FormatError(f"{where} = {value!r} must be a list of 3 {what}")
    return tuple(_number(v, f"{where}[{i}]", lo, hi) for i, v in enumerate(value))


def _rgb(value, where, hi=MAX_RGB):
    return _triple(value, where, 0.0, hi, f"numbers in [0, {hi:g}] (RGB)")


def _string(value, where):
    if not isinstance(value, str) or not value:
        raise FormatError(f"{where} = {value!r} must be a non-empty string")
    return value


def _table(value, where):
    if not isinstance(value, dict):
        raise FormatError(f"{where} must be a table, got {type(value).__name__}")
    return value


def _known_keys(table, known, where, lenient):
    for key in table:
        if key not in known and not lenient:
            raise FormatError(f"{where}: unknown key {key!r} (known: {', '.join(sorted(known))})")


def _file(value, where, base):
    path = (base / _string(value, where)).resolve()
    if not path.exists():
        raise FormatError(f"{where} = {value!r}: file not found ({path})")
    try:
        return regular_file(path, "a file")
    except FormatError as e:
        raise FormatError(f"{where} = {value!r}: {e}") from None


def _exactly_one(table, keys, where):
    given = [k for k in keys if k in table]
    if len(given) != 1:
        raise FormatError(f"{where}: give exactly one of {' or '.join(keys)}, got "
                          f"{', '.join(given) if given else 'none'}")
    return given[0]


# --- sections -------------------------------------------------------------------------------------------------------

def _camera(raw, where, lenient):
    raw = _table(raw, where)
    _known_keys(raw, {"position", "look_at", "up", "fov_deg", "ortho_height", "width", "height"}, where, lenient)
    for key in ("position", "look_at", "width", "height"):
        if key not in raw:
            raise FormatError(f"{where}.{key} is missing (required)")
    position = _triple(raw["position"], f"{where}.position")
    look_at = _triple(raw["look_at"], f"{where}.look_at")
    up = _triple(raw.get("up", [0.0, 1.0, 0.0]), f"{where}.up")
    view = [b - a for a, b in zip(position, look_at)]
    cross = [view[1] * up[2] - view[2] * up[1], view[2] * up[0] - view[0] * up[2], view[0] * up[1] - view[1] * up[0]]
    norm = lambda v: math.sqrt(sum(x * x for x in v))  # noqa: E731
    if norm(view) == 0:
        raise FormatError(f"{where}.look_at = {list(look_at)} equals position, expected a point the camera looks at")
    if norm(cross) <= 1e-6 * norm(view) * norm(up):
        raise FormatError(f"{where}.up = {list(up)} is zero or parallel to the view direction {view}, expected a "
                          f"vector not parallel to look_at - position")
    kind = _exactly_one(raw, ("fov_deg", "ortho_height"), where)
    fov = _number(raw["fov_deg"], f"{where}.fov_deg", 0, 180, True, True, "degrees") if kind == "fov_deg" else None
    ortho = (_number(raw["ortho_height"], f"{where}.ortho_height", 0, 1e9, lo_open=True, unit="scene units")
             if kind == "ortho_height" else None)
    return Camera(position, look_at, up, fov, ortho, _integer(raw["width"], f"{where}.width", 1, MAX_IMAGE_SIZE),
                  _integer(raw["height"], f"{where}.height", 1, MAX_IMAGE_SIZE))


def _light(raw, where, base, lenient):
    raw = _table(raw, where)
    kind = raw.get("type")
    if kind not in LIGHT_TYPES:
        raise FormatError(f"{where}.type = {kind!r} is not a light type (allowed: {', '.join(LIGHT_TYPES)})")
    if kind == "directional":
        _known_keys(raw, {"type", "direction", "irradiance"}, where, lenient)
        for key in ("direction", "irradiance"):
            if key not in raw:
                raise FormatError(f"{where}.{key} is missing (required for a directional light)")
        d = _triple(raw["direction"], f"{where}.direction")
        if not math.hypot(*d) > 0:
            raise FormatError(f"{where}.direction = {list(d)} is zero, expected a direction toward the light")
        return DirectionalLight(d, _rgb(raw["irradiance"], f"{where}.irradiance"))
    _known_keys(raw, {"type", "file", "builtin", "scale"}, where, lenient)
    source = _exactly_one(raw, ("file", "builtin"), where)
    builtin = raw.get("builtin")
    if source == "builtin" and builtin not in BUILTIN_ENVIRONMENTS:
        raise FormatError(f"{where}.builtin = {builtin!r} is not a builtin environment (allowed: "
                          f"{', '.join(BUILTIN_ENVIRONMENTS)})")
    file = _file(raw["file"], f"{where}.file", base) if source == "file" else None
    return EnvironmentLight(file, builtin, _rgb(raw.get("scale", [1.0, 1.0, 1.0]), f"{where}.scale"))


def _render(raw, where, lenient):
    raw = _table(raw, where)
    _known_keys(raw, set(RENDER_FIELDS), where, lenient)
    values = {key: _integer(raw.get(key, default), f"{where}.{key}", lo, hi)
              for key, (default, lo, hi, _) in RENDER_FIELDS.items()}
    if values["msaa"] not in MSAA_LEVELS:
        raise FormatError(f"{where}.msaa = {values['msaa']} is not allowed (allowed: "
                          f"{', '.join(map(str, MSAA_LEVELS))})")
    size = values["shadow_map_size"]
    if size & (size - 1):
        raise FormatError(f"{where}.shadow_map_size = {size} is not a power of two (allowed 64, 128, ..., 16384)")
    return RenderSettings(**values)


def _resolve_yarn(value, where, base):
    value = _string(value, where)
    if value.endswith(".toml"):
        path = _file(value, where, base)
        return str(path), load_spec(path)
    if value not in preset_names():
        raise FormatError(f"{where} = {value!r} is neither a preset ({', '.join(preset_names())}) nor a yarn-spec "
                          f"path ending in .toml")
    return value, load_preset(value)


def curve_file_facts(path, where):
    """(yarn_types, units, frames) of a knit-yarn-curves or BCC file, read without loading its points."""
    if yarn_curves.sniff(path):
        try:
            with open_hdf5(path, "a knit-yarn-curves file") as f:
                units = f.attrs["units"]
                units = units.decode() if isinstance(units, bytes) else str(units)
                return [str(s) for s in f["yarn_types"].asstr()[()]], units, int(f["points"].shape[0])
        except Exception as e:  # a damaged file: the curve reader's own validate() names the problem
            raise FormatError(f"{where} = {str(path)!r}: unreadable yarn-curves file ({type(e).__name__}: "
                              f"{' '.join(str(e).split())}); run 'knitbake validate' on it") from None
    if bcc.sniff(path):
        return ["unknown"], "unknown", 1
    raise FormatError(f"{where} = {str(path)!r} is not a knit-yarn-curves HDF5 or BCC file")


def read_curves(path, units: str):
    """The yarn curves of a scene entry's ``curves`` file, by content: our HDF5 file, or BCC (which stores no unit:
    it is read in the scene's ``units``)."""
    return bcc.read_bcc(path, units=units) if bcc.sniff(path) else yarn_curves.read_yarn_curves(path)


def _yarn(raw, where, base, units, lenient, facts):
    """One [[yarns]] entry; ``facts`` caches ``curve_file_facts`` by path."""
    raw = _table(raw, where)
    _known_keys(raw, {"curves", "stitch_mesh", "yarn_type", "yarn", "radius", "pack", "color"}, where, lenient)
    source = _exactly_one(raw, ("curves", "stitch_mesh"), where)
    path = _file(raw[source], f"{where}.{source}", base)
    if "yarn" not in raw:
        raise FormatError(f"{where}.yarn is missing (required: a preset name or a yarn-spec .toml path)")
    yarn, spec = _resolve_yarn(raw["yarn"], f"{where}.yarn", base)
    selected = raw.get("yarn_type")
    if selected is not None and (isinstance(selected, bool) or not isinstance(selected, (str, int))):
        raise FormatError(f"{where}.yarn_type = {selected!r} must be a yarn-type name or a 0-based index")
    indices = ()
    if source == "curves":
        if path not in facts:
            facts[path] = curve_file_facts(path, f"{where}.curves")
        types, file_units, _ = facts[path]
        if file_units not in (units, "unknown"):
            raise FormatError(f"{where}.curves = {raw['curves']!r} is in units {file_units!r}, expected the scene's "
                              f"units {units!r}")
        if selected is None:
            indices = tuple(range(len(types)))
        elif isinstance(selected, int):
            indices = (_integer(selected, f"{where}.yarn_type", 0, len(types) - 1),)
        elif selected in types:
            indices = (types.index(selected),)
        else:
            raise FormatError(f"{where}.yarn_type = {selected!r} is not a yarn type of {raw['curves']!r} "
                              f"(its yarn_types: {', '.join(types)})")
    default_radius = spec.radius * CM_PER_UNIT[spec.units] / CM_PER_UNIT[units]
    radius = _number(raw.get("radius", default_radius), f"{where}.radius", 0, 1e6, lo_open=True, unit=units)
    pack = (base / _string(raw["pack"], f"{where}.pack")).resolve() if "pack" in raw else None
    color = _rgb(raw.get("color", [1.0, 1.0, 1.0]), f"{where}.color", hi=1.0)
    return YarnEntry(path if source == "curves" else None, path if source == "stitch_mesh" else None, selected,
                     yarn, spec, radius, pack, color, indices)


def _check_assignment(yarns, source, facts):
    """Each yarn type of each curve file drawn by exactly one entry (``facts``: ``curve_file_facts`` by path)."""
    owner = {}
    for i, entry in enumerate(yarns):
        if entry.curves is None:
            continue
        for t in entry.yarn_type_indices:
            j = owner.setdefault((entry.curves, t), i)
            if j != i:
                raise FormatError(f"{source}: yarns[{i}] and yarns[{j}] both draw yarn type {t} of {entry.curves}, "
                                  f"expected each yarn type drawn by one entry (set yarn_type)")
    for entry in yarns:
        if entry.curves is None:
            continue
        types = facts[entry.curves][0]
        missing = [types[t] for t in range(len(types)) if (entry.curves, t) not in owner]
        if missing:
            raise FormatError(f"{source}: yarn types {missing} of {entry.curves} are drawn by no [[yarns]] entry, "
                              f"expected every yarn type drawn (add an entry with yarn_type)")


# --- load / dump ----------------------------------------------------------------------------------------------------

def scene_from_dict(data: dict, source: str, base: Path) -> Scene:
    """Build and validate a Scene from parsed TOML; relative paths are resolved against ``base``."""
    data = _table(data, source)
    fmt = data.get("format")
    if fmt != FORMAT_NAME:
        raise FormatError(f"{source}: format = {fmt!r}, expected {FORMAT_NAME!r}")
    version = str(data.get("version", ""))
    major, _, minor = version.partition(".")
    if major != FORMAT_VERSION.split(".")[0] or not minor.isdigit():
        raise FormatError(f"{source}: version = {version!r}, expected {FORMAT_VERSION!r} (this reader knows 1.x)")
    lenient = int(minor) > int(FORMAT_VERSION.split(".")[1])  # a newer minor only adds optional keys
    _known_keys(data, {"format", "version", "name", "description", "units", "background", "yarns", "camera",
                       "lights", "render"}, source, lenient)
    units = data.get("units")
    if units not in LENGTH_UNITS:
        raise FormatError(f"{source}: units = {units!r} is not one of {', '.join(LENGTH_UNITS)}")
    for key in ("yarns", "camera", "lights"):
        if key not in data:
            raise FormatError(f"{source}: {key} is missing (required; see SCENE.md)")
    for key in ("yarns", "lights"):
        if not isinstance(data[key], list) or not data[key]:
            raise FormatError(f"{source}: {key} = {data[key]!r:.60} must be a non-empty array of tables "
                              f"([[{key}]])")
    facts = {}
    yarns = tuple(_yarn(raw, f"{source}: yarns[{i}]", base, units, lenient, facts)
                  for i, raw in enumerate(data["yarns"]))
    _check_assignment(yarns, source, facts)
    lights = tuple(_light(raw, f"{source}: lights[{i}]", base, lenient) for i, raw in enumerate(data["lights"]))
    if sum(isinstance(light, EnvironmentLight) for light in lights) > 1:
        raise FormatError(f"{source}: lights has more than one environment light, expected at most one")
    render = _render(data.get("render", {}), f"{source}: render", lenient)
    for i, entry in enumerate(yarns):
        if entry.curves is not None:
            frames = facts[entry.curves][2]
            if render.frame >= frames:
                raise FormatError(f"{source}: render.frame = {render.frame} is out of range for yarns[{i}].curves "
                                  f"({frames} frames, allowed [0, {frames - 1}])")
    return Scene(units, yarns, _camera(data["camera"], f"{source}: camera", lenient), lights,
                 _rgb(data.get("background", [0.0, 0.0, 0.0]), f"{source}: background"), render,
                 str(data.get("name", "")), str(data.get("description", "")))


def load_scene(path) -> Scene:
    """Read and validate a scene file; raise ``FormatError`` (one line) on any problem, including a missing
    curve, stitch-mesh, yarn-spec or environment file. A missing ``pack`` is not an error here (``validate``
    reports it): a scene may name the pack it is baked for."""
    path = regular_file(path, "a scene file (.toml)")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise FormatError(f"{path}: cannot read scene ({type(e).__name__}: {' '.join(str(e).split())})") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise FormatError(f"{path}: not valid TOML ({' '.join(str(e).split())})") from None
    return scene_from_dict(data, str(path), path.resolve().parent)


def _rel(path: Path, base: Path) -> str:
    try:
        return Path(os.path.relpath(path, base)).as_posix()
    except ValueError:  # another drive (Windows): keep it absolute
        return path.as_posix()


def scene_to_dict(scene: Scene, base: Path) -> dict:
    """The TOML table of ``scene`` with paths relative to ``base`` (every field written, defaults included)."""
    yarns = []
    for e in scene.yarns:
        item = {"curves": _rel(e.curves, base)} if e.curves else {"stitch_mesh": _rel(e.stitch_mesh, base)}
        if e.yarn_type is not None:
            item["yarn_type"] = e.yarn_type
        item["yarn"] = _rel(Path(e.yarn), base) if e.yarn.endswith(".toml") else e.yarn
        item.update(radius=e.radius, color=list(e.color))
        if e.pack:
            item["pack"] = _rel(e.pack, base)
        yarns.append(item)
    c = scene.camera
    camera = {"position": list(c.position), "look_at": list(c.look_at), "up": list(c.up)}
    camera.update({"fov_deg": c.fov_deg} if c.fov_deg is not None else {"ortho_height": c.ortho_height})
    camera.update(width=c.width, height=c.height)
    lights = []
    for light in scene.lights:
        if isinstance(light, DirectionalLight):
            lights.append({"type": "directional", "direction": list(light.direction),
                           "irradiance": list(light.irradiance)})
        else:
            src = {"file": _rel(light.file, base)} if light.file else {"builtin": light.builtin}
            lights.append({"type": "environment", **src, "scale": list(light.scale)})
    return {"format": FORMAT_NAME, "version": FORMAT_VERSION, "name": scene.name, "description": scene.description,
            "units": scene.units, "background": list(scene.background), "camera": camera,
            "render": dataclasses.asdict(scene.render), "yarns": yarns, "lights": lights}


def dumps_scene(scene: Scene, base) -> str:
    """``scene`` as TOML text with paths relative to the folder ``base``."""
    return tomli_w.dumps(scene_to_dict(scene, Path(base).resolve()))


def save_scene(path, scene: Scene) -> None:
    """Write ``scene`` atomically to ``path`` (paths relative to its folder)."""
    path = Path(path)
    text = dumps_scene(scene, path.resolve().parent)
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


# --- inspect / validate hooks ---------------------------------------------------------------------------------------

def sniff(path) -> bool:
    """True if ``path`` is a TOML file whose top-level ``format`` is ``"knit-scene"``; never raises."""
    head = read_head(path, 1 << 20)
    if head is None:
        return False
    try:
        data = tomllib.loads(head.decode("utf-8"))
        return data.get("format") == FORMAT_NAME
    except Exception:
        return False


def describe(path) -> dict:
    """JSON-serialisable summary of a scene file; raises ``FormatError`` if it is invalid."""
    scene = load_scene(path)
    asdict = scene_to_dict(scene, Path(path).resolve().parent)
    for item, entry in zip(asdict["yarns"], scene.yarns):
        item["yarn_type_indices"] = list(entry.yarn_type_indices)
        item["spec_radius"] = entry.spec.radius
    return {"kind": "scene", **asdict, "projection": "orthographic" if scene.camera.fov_deg is None else "perspective"}


def validate(path) -> list[str]:
    """Problems of a scene file and of the curve files it references, and missing packs (empty list: valid);
    never raises for bad content."""
    try:
        scene = load_scene(path)
    except FormatError as e:
        return [str(e)]
    problems, seen = [], set()
    for i, entry in enumerate(scene.yarns):
        if entry.curves is not None and entry.curves not in seen:
            seen.add(entry.curves)
            module = yarn_curves if yarn_curves.sniff(entry.curves) else bcc
            problems += [f"{path}: yarns[{i}].curves: {p}" for p in module.validate(entry.curves)]
        if entry.pack is not None and not entry.pack.is_file():
            problems.append(f"{path}: yarns[{i}].pack: file not found ({entry.pack}); bake it with "
                            f"'knitbake bake {entry.yarn} -o {entry.pack}'")
    return problems
