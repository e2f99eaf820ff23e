"""Yarn specification: one yarn type as a TOML file (procedural geometry, flyaways, fiber optics).

Units and conventions
---------------------
* Every length is in the file's ``units`` (``"mm"``, ``"cm"`` or ``"m"``; all presets use ``"cm"``). Densities of
  flyaways are counts per unit length per ply. Optical angles are in degrees in the file.
* Geometry follows the procedural yarn model of Zhao et al. 2016 as written in Wu and Yuksel 2019 §2.2/§3.1:
  K plies whose centres lie on a helix of radius ``ply_distance`` around the yarn axis with pitch ``ply_pitch``
  (length per full turn); in each ply ``fibers_per_ply`` fibers, each a helix around the ply centre with pitch
  ``fiber_pitch``, placed by the cross-section density p(R) = (1−2ε)((e − e^R)/(e − 1))^β + ε on the unit disk
  (R_max = 1), migrating between ``migration_rho_min``·R_i and ``migration_rho_max``·R_i with frequency
  ``migration_frequency`` (s: migration cycles per fiber turn). The normalised ply cross-section is scaled to an
  ellipse with semi-axes ``ply_semi_axes = [along the ply's binormal (tangential, long), along its normal
  (radial, short)]``.
* Flyaways (Huang et al. 2025 eqs. 12–13): hair fibers R(t) = R_0 + R_e(1 − (1 − t)^α), θ(t) = θ_0 + θ_e t,
  z(t) = z_0 + z_e t around the ply centre, with Gaussian noise on their direction of progress; loop fibers raise
  one migration cycle of a fiber to ``loop_radius`` (distance from the ply centre). Every random quantity is a
  Gaussian given by ``*_mean`` and ``*_std``.
* Optics: the fiber BCSDF of Huang et al. 2025 eq. 7 (R, TT and D lobes): lobe colours are RGB albedo weights in [0, 1],
  β are longitudinal widths, γ_TT the azimuthal TT width, α the longitudinal shifts.

The field table ``FIELDS`` is the single schema: it drives parsing, validation, defaults, the written spec
(``YARN_SPEC.md``) and ``knitbake yarn show``.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from pathlib import Path

import numpy as np
import tomli_w

from .atomic import atomic_path
from .conventions import LENGTH_UNITS
from .errors import FormatError
from .input_files import read_head, regular_file

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

FORMAT_NAME = "knit-yarn-spec"
FORMAT_VERSION = "1.0"
PRESET_DIR = Path(__file__).parent / "presets"


@dataclasses.dataclass(frozen=True)
class Field:
    """One spec field: TOML section and key, type, allowed closed range, default (None = required), unit, doc."""

    section: str
    key: str
    kind: str  # "int", "float", "bool", "pair" (two floats), "rgb" (three floats)
    lo: float
    hi: float
    default: object
    unit: str
    doc: str


def _f(section, key, kind, lo, hi, default, unit, doc):
    return Field(section, key, kind, lo, hi, default, unit, doc)


FIELDS = (
    _f("geometry", "plies", "int", 1, 16, None, "", "K, number of plies"),
    _f("geometry", "fibers_per_ply", "int", 1, 1000, None, "", "m, regular fibers per ply (measured yarns: 33–150; "
       "the period matching costs ~m^2.5: 7 s at 1000)"),
    _f("geometry", "ply_pitch", "float", 1e-6, 1e6, None, "length", "α_yarn: length of one full turn of the plies"),
    _f("geometry", "fiber_pitch", "float", 1e-6, 1e6, None, "length",
       "α_fiber: length of one full turn of a fiber around its ply centre"),
    _f("geometry", "ply_clockwise", "bool", 0, 1, False, "", "plies turn clockwise seen along +z"),
    _f("geometry", "fiber_clockwise", "bool", 0, 1, True, "", "fibers turn clockwise (in the ply frame)"),
    _f("geometry", "ply_distance", "float", 0.0, 1e6, None, "length", "distance of a ply centre from the yarn axis"),
    _f("geometry", "ply_semi_axes", "pair", 1e-9, 1e6, None, "length",
       "ply ellipse semi-axes [binormal (tangential), normal (radial)]"),
    _f("geometry", "fiber_radius", "float", 1e-9, 1e6, None, "length", "radius of one fiber"),
    _f("geometry", "density_eps", "float", 0.0, 0.5, None, "", "ε of the cross-section density p(R)"),
    _f("geometry", "density_beta", "float", 0.0, 100.0, None, "", "β of the cross-section density p(R)"),
    _f("geometry", "migration_rho_min", "float", 0.0, 1.0, None, "", "ρ_min: migration minimum (× R_i)"),
    _f("geometry", "migration_rho_max", "float", 0.0, 1.0, 1.0, "", "ρ_max: migration maximum (× R_i)"),
    _f("geometry", "migration_frequency", "float", 0.0, 100.0, None, "", "s: migration cycles per fiber turn"),
    _f("flyaways", "hair_density", "float", 0.0, 1e6, 0.0, "1/length", "ρ_hair: hair fibers per unit length per ply"),
    _f("flyaways", "hair_z_span_mean", "float", -1e6, 1e6, 0.0, "length", "z_e: axial span of a hair"),
    _f("flyaways", "hair_z_span_std", "float", 0.0, 1e6, 0.0, "length", ""),
    _f("flyaways", "hair_start_radius_mean", "float", 0.0, 1e6, 0.0, "length", "R_0: start distance from the ply centre"),
    _f("flyaways", "hair_start_radius_std", "float", 0.0, 1e6, 0.0, "length", ""),
    _f("flyaways", "hair_radial_span_mean", "float", -1e6, 1e6, 0.0, "length", "R_e: radial span of a hair"),
    _f("flyaways", "hair_radial_span_std", "float", 0.0, 1e6, 0.0, "length", ""),
    _f("flyaways", "hair_angular_span_mean", "float", -100.0, 100.0, 0.0, "rad", "θ_e: angular span of a hair"),
    _f("flyaways", "hair_angular_span_std", "float", 0.0, 100.0, 0.0, "rad", ""),
    _f("flyaways", "hair_curvature_alpha", "float", 0.05, 20.0, 1.0, "",
       "α of Huang et al. 2025 eq. 13 (1 = straight radial growth, >1 bends out early)"),
    _f("flyaways", "hair_direction_noise", "float", 0.0, 1.0, 0.0, "rad",
       "std of the random turn of a hair's direction of progress per unit of t"),
    _f("flyaways", "loop_density", "float", 0.0, 1e6, 0.0, "1/length", "ρ_loop: loop fibers per unit length per ply"),
    _f("flyaways", "loop_radius_mean", "float", 0.0, 1e6, 0.0, "length", "R_loop: peak distance from the ply centre"),
    _f("flyaways", "loop_radius_std", "float", 0.0, 1e6, 0.0, "length", ""),
    _f("optics", "r_color", "rgb", 0.0, 1.0, None, "", "A_R: reflection lobe colour"),
    _f("optics", "tt_color", "rgb", 0.0, 1.0, None, "", "A_TT: transmission lobe colour"),
    _f("optics", "d_color", "rgb", 0.0, 1.0, (0.0, 0.0, 0.0), "", "A_D: diffuse (in-fiber multiple scattering) colour"),
    _f("optics", "beta_r_deg", "float", 1e-3, 90.0, None, "deg", "β_R: longitudinal width of R"),
    _f("optics", "beta_tt_deg", "float", 1e-3, 90.0, None, "deg", "β_TT: longitudinal width of TT"),
    _f("optics", "gamma_tt_deg", "float", 1e-3, 180.0, None, "deg", "γ_TT: azimuthal width of TT"),
    _f("optics", "alpha_r_deg", "float", -45.0, 45.0, 0.0, "deg", "α_R: longitudinal shift of R"),
    _f("optics", "alpha_tt_deg", "float", -45.0, 45.0, 0.0, "deg", "α_TT: longitudinal shift of TT"),
)
SECTIONS = ("geometry", "flyaways", "optics")


def _section_class(section):
    names = [(f.key, object) for f in FIELDS if f.section == section]
    cls = dataclasses.make_dataclass(section.capitalize(), names, frozen=True)
    cls.__module__ = __name__  # make_dataclass says "types", where pickle cannot find the class
    return cls


Geometry = _section_class("geometry")
Flyaways = _section_class("flyaways")
Optics = _section_class("optics")
_CLASSES = {"geometry": Geometry, "flyaways": Flyaways, "optics": Optics}


@dataclasses.dataclass(frozen=True)
class YarnSpec:
    """A validated yarn type. Lengths in ``units``; see the module docstring for every convention."""

    name: str
    units: str
    description: str
    provenance: dict
    geometry: Geometry
    flyaways: Flyaways
    optics: Optics

    @property
    def has_flyaways(self) -> bool:
        return self.flyaways.hair_density > 0 or self.flyaways.loop_density > 0

    @property
    def ply_radius(self) -> float:
        """Largest semi-axis of a ply's cross-section (length)."""
        return max(self.geometry.ply_semi_axes)

    @property
    def radius(self) -> float:
        """Outer radius of the regular fibers around the yarn axis (length): the farthest point of a ply's ellipse
        scaled by the migration maximum, plus one fiber radius."""
        g = self.geometry
        t = np.linspace(0.0, np.pi, 721)
        a, b = g.ply_semi_axes[0] * g.migration_rho_max, g.ply_semi_axes[1] * g.migration_rho_max
        return float(np.max(np.hypot(g.ply_distance + b * np.cos(t), a * np.sin(t)))) + g.fiber_radius


def fiber_bcsdf_attrs(optics: Optics) -> dict:
    """The fiber BCSDF of a spec's optics as an asset pack's ``/fiber_bcsdf`` attributes: lobe colours as given,
    angles converted from the spec's degrees to radians (the one place this conversion is made)."""
    o = optics
    return {"r_color": list(o.r_color), "tt_color": list(o.tt_color), "d_color": list(o.d_color),
            "beta_r": math.radians(o.beta_r_deg), "beta_tt": math.radians(o.beta_tt_deg),
            "gamma_tt": math.radians(o.gamma_tt_deg), "alpha_r": math.radians(o.alpha_r_deg),
            "alpha_tt": math.radians(o.alpha_tt_deg)}


def _where(source, section, key):
    return f"{source}: [{section}] {key}"


def _check_number(value, field, source):
    where = _where(source, field.section, field.key)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise FormatError(f"{where} = {value!r} is not a number")
    try:
        v = float(value)
    except OverflowError:
        v = math.inf
    if not math.isfinite(v):
        raise FormatError(f"{where} = {value!r} is not finite (allowed [{field.lo:g}, {field.hi:g}])")
    if not field.lo <= v <= field.hi:
        raise FormatError(f"{where} = {value!r} is out of range (allowed [{field.lo:g}, {field.hi:g}]"
                          f"{' ' + field.unit if field.unit else ''})")
    return v


def _parse_field(value, field, source):
    where = _where(source, field.section, field.key)
    if field.kind == "int":
        if isinstance(value, bool) or not isinstance(value, int):
            raise FormatError(f"{where} = {value!r} must be an integer in [{field.lo:g}, {field.hi:g}]")
        _check_number(value, field, source)
        return int(value)
    if field.kind == "bool":
        if not isinstance(value, bool):
            raise FormatError(f"{where} = {value!r} must be true or false")
        return value
    if field.kind in ("pair", "rgb"):
        n = 2 if field.kind == "pair" else 3
        if not isinstance(value, (list, tuple)) or len(value) != n:
            raise FormatError(f"{where} = {value!r} must be a list of {n} numbers in [{field.lo:g}, {field.hi:g}]")
        return tuple(_check_number(v, field, source) for v in value)
    return _check_number(value, field, source)


def _cross_checks(spec: YarnSpec, source: str):
    g, fl = spec.geometry, spec.flyaways
    if g.migration_rho_min > g.migration_rho_max:
        raise FormatError(f"{_where(source, 'geometry', 'migration_rho_min')} = {g.migration_rho_min} exceeds "
                          f"migration_rho_max = {g.migration_rho_max} (allowed [0, migration_rho_max])")
    if g.fiber_radius >= min(g.ply_semi_axes):
        raise FormatError(f"{_where(source, 'geometry', 'fiber_radius')} = {g.fiber_radius} is not smaller than the "
                          f"smallest ply semi-axis {min(g.ply_semi_axes)} (allowed (0, {min(g.ply_semi_axes)}))")
    if g.plies > 1 and g.ply_distance <= 0.0:
        raise FormatError(f"{_where(source, 'geometry', 'ply_distance')} = {g.ply_distance} must be > 0 when "
                          f"plies = {g.plies} > 1")
    o = spec.optics
    albedo = [r + t + d for r, t, d in zip(o.r_color, o.tt_color, o.d_color)]
    if max(albedo) > 1.0 + 1e-9:
        raise FormatError(f"{source}: [optics] r_color + tt_color + d_color = {[round(a, 6) for a in albedo]} exceeds 1 "
                          f"(the lobe colours are albedos of an energy-conserving fiber: their sum must be ≤ 1 per "
                          f"channel)")
    if fl.hair_density > 0 and fl.hair_start_radius_mean <= 0:
        raise FormatError(f"{_where(source, 'flyaways', 'hair_start_radius_mean')} = {fl.hair_start_radius_mean} "
                          f"must be > 0 when hair_density > 0")
    if fl.loop_density > 0 and fl.loop_radius_mean <= 0:
        raise FormatError(f"{_where(source, 'flyaways', 'loop_radius_mean')} = {fl.loop_radius_mean} "
                          f"must be > 0 when loop_density > 0")


def spec_from_dict(data: dict, source: str = "<yarn spec>") -> YarnSpec:
    """Build and validate a YarnSpec from parsed TOML. Raises FormatError naming the bad field, value and range."""
    if not isinstance(data, dict):
        raise FormatError(f"{source}: not a TOML table")
    fmt = data.get("format", FORMAT_NAME)
    if fmt != FORMAT_NAME:
        raise FormatError(f"{source}: format = {fmt!r}, expected {FORMAT_NAME!r}")
    version = str(data.get("version", FORMAT_VERSION))
    major, _, minor = version.partition(".")
    if major != FORMAT_VERSION.split(".")[0] or not minor.isdigit():
        raise FormatError(f"{source}: version = {version!r} has an unknown major version (this reader knows "
                          f"{FORMAT_VERSION})")
    # A newer minor version only adds optional keys: ignore the ones this reader does not know. Otherwise an
    # unknown key is a typo and is refused.
    newer_minor = int(minor) > int(FORMAT_VERSION.split(".")[1])
    name = data.get("name")
    if not isinstance(name, str) or not name.strip():
        raise FormatError(f"{source}: name = {name!r} must be a non-empty string")
    units = data.get("units", "cm")
    if units not in LENGTH_UNITS:
        raise FormatError(f"{source}: units = {units!r} is not one of {', '.join(LENGTH_UNITS)}")
    known_top = {"format", "version", "name", "units", "description", "provenance", *SECTIONS}
    for key in data:
        if key not in known_top and not newer_minor:
            raise FormatError(f"{source}: unknown top-level key {key!r} (known: {', '.join(sorted(known_top))})")
    provenance = data.get("provenance", {})
    if not isinstance(provenance, dict) or not all(isinstance(v, str) for v in provenance.values()):
        raise FormatError(f"{source}: [provenance] must be a table of strings")
    sections = {}
    for section in SECTIONS:
        raw = data.get(section, {})
        if not isinstance(raw, dict):
            raise FormatError(f"{source}: [{section}] must be a table")
        fields = [f for f in FIELDS if f.section == section]
        known = {f.key for f in fields}
        for key in raw:
            if key not in known and not newer_minor:
                raise FormatError(f"{source}: [{section}] unknown key {key!r} (known: {', '.join(sorted(known))})")
        values = {}
        for f in fields:
            if f.key in raw:
                values[f.key] = _parse_field(raw[f.key], f, source)
            elif f.default is None:
                raise FormatError(f"{_where(source, section, f.key)} is missing (required; allowed "
                                  f"[{f.lo:g}, {f.hi:g}]{' ' + f.unit if f.unit else ''})")
            else:
                values[f.key] = f.default
        sections[section] = _CLASSES[section](**values)
    spec = YarnSpec(name=name, units=units, description=str(data.get("description", "")),
                    provenance=dict(provenance), **sections)
    _cross_checks(spec, source)
    return spec


def spec_to_dict(spec: YarnSpec) -> dict:
    """The TOML table of a spec (every field written, defaults included)."""
    out = {"format": FORMAT_NAME, "version": FORMAT_VERSION, "name": spec.name, "units": spec.units,
           "description": spec.description, "provenance": dict(spec.provenance)}
    for section in SECTIONS:
        obj = getattr(spec, section)
        out[section] = {f.key: (list(v) if isinstance(v := getattr(obj, f.key), tuple) else v)
                        for f in FIELDS if f.section == section}
    return out


def loads_spec(text: str, source: str = "<yarn spec>") -> YarnSpec:
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise FormatError(f"{source}: not valid TOML ({exc})") from None
    return spec_from_dict(data, source)


def dumps_spec(spec: YarnSpec) -> str:
    return tomli_w.dumps(spec_to_dict(spec))


def load_spec(path) -> YarnSpec:
    path = regular_file(path, "a yarn spec (.toml)")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise FormatError(f"{path}: cannot read yarn spec ({exc.__class__.__name__}: {exc})") from None
    return loads_spec(text, str(path))


def save_spec(path, spec: YarnSpec) -> None:
    """Write ``spec`` as TOML atomically (validated by construction)."""
    text = dumps_spec(spec)
    with atomic_path(path) as tmp:
        Path(tmp).write_text(text, encoding="utf-8")


def preset_names() -> list[str]:
    return sorted(p.stem for p in PRESET_DIR.glob("*.toml"))


def load_preset(name: str) -> YarnSpec:
    path = PRESET_DIR / f"{name}.toml"
    if not path.is_file():
        raise FormatError(f"unknown yarn preset {name!r} (presets: {', '.join(preset_names())})")
    return load_spec(path)


def resolve_yarn(name_or_path: str) -> YarnSpec:
    """A preset name, or a path to a yarn-spec TOML file."""
    if Path(name_or_path).is_file():
        return load_spec(name_or_path)
    if name_or_path in preset_names():
        return load_preset(name_or_path)
    raise FormatError(f"{name_or_path!r} is neither a yarn preset ({', '.join(preset_names())}) nor a file")


# --- inspect / validate hooks -------------------------------------------------------------------------------------

def sniff(path) -> bool:
    """True if ``path`` is a TOML file that declares itself a yarn spec (format key), or has [geometry] and
    [optics] tables."""
    head = read_head(path, 1 << 16)
    if head is None:
        return False
    try:
        data = tomllib.loads(head.decode("utf-8"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError):
        return False
    return data.get("format") == FORMAT_NAME or ("geometry" in data and "optics" in data)


def describe_spec(spec: YarnSpec) -> dict:
    g, fl = spec.geometry, spec.flyaways
    return {"kind": "yarn-spec", "name": spec.name, "units": spec.units, "description": spec.description,
            "plies": g.plies, "fibers": g.plies * g.fibers_per_ply, "radius": spec.radius,
            "period": g.ply_pitch, "has_flyaways": spec.has_flyaways,
            "flyaways_per_length": g.plies * (fl.hair_density + fl.loop_density),
            "provenance": dict(spec.provenance), "spec": spec_to_dict(spec)}


def describe(path) -> dict:
    return describe_spec(load_spec(path))


def validate(path) -> list[str]:
    try:
        load_spec(path)
    except FormatError as exc:
        return [str(exc)]
    return []


def schema_markdown() -> str:
    """The field table of YARN_SPEC.md, generated from FIELDS."""
    rows = ["| section | key | type | allowed | default | unit | meaning |", "|---|---|---|---|---|---|---|"]
    for f in FIELDS:
        default = "required" if f.default is None else repr(f.default)
        rows.append(f"| {f.section} | `{f.key}` | {f.kind} | [{f.lo:g}, {f.hi:g}] | {default} | {f.unit} | {f.doc} |")
    return "\n".join(rows)
