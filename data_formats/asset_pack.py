"""Asset pack: everything baked for one yarn type, in one HDF5 file (``format = "knit-asset-pack"``).

The written specification a third-party renderer needs is ``ASSET_PACK.md`` (next to this file). In short:

* Root attrs ``format``, ``schema_version`` ("major.minor"). A reader MUST refuse an unknown major version and
  accept a higher minor one (ignoring members it does not know).
* Groups ``/yarn``, ``/provenance``, ``/fiber_bcsdf`` hold attributes only (``ATTRS``).
* Every baked table is OPTIONAL (``TABLES``): one float32 dataset per table, self-describing axes
  (``axes``, ``axis{i}_range``, ``axis{i}_wrap``, ``axis{i}_units``, ``axis{i}_samples``), sampled at cell centres
  of a uniform grid, and an error bar (``error_estimate``, ``error_kind``, ``error_statistic``, and a same-shape
  ``<name>_stderr`` dataset where per-entry errors exist).

``ATTRS`` and ``TABLES`` are the single schema: the writer, the reader and the validator all check through the
same functions (``_attr_problem``, ``_table_meta_problems``, ``_shape_problems``, ``_numeric_problems``), so what
one accepts the others accept.
"""

from __future__ import annotations

import dataclasses
import datetime
import json
import math
import re
import sys
from pathlib import Path

import h5py
import numpy as np

from .atomic import atomic_path
from .errors import FormatError
from .hdf5_fields import HDF5_MAGIC
from .jsonable import jsonable
from .yarn_spec import UNITS as LENGTH_UNITS

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

FORMAT_NAME = "knit-asset-pack"
SCHEMA_VERSION = "2.0"
SCHEMA_MAJOR, SCHEMA_MINOR = (int(p) for p in SCHEMA_VERSION.split("."))
TABLE_DTYPE = np.dtype("<f4")
MAX_MIP_LEVELS = 16
COMPRESS_BYTES = 1 << 16  # datasets at least this large are stored gzip(4)+shuffle
STDERR_SUFFIX = "_stderr"
DEFAULT_ERROR_KIND = "standard error of the mean over independent sample batches"
HALF_PI = math.pi / 2


# --- axes ---------------------------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class Axis:
    """One axis of a table. ``sampled`` axes carry a uniform cell-centre grid over ``range`` (interpolated
    linearly, ``wrap`` = "clamp" or "repeat"); index axes (channel, variant) are not interpolated."""

    name: str
    sampled: bool
    range: tuple | None
    wrap: str | None
    units: str
    definition: str
    store_samples: bool = True  # texture u/v axes: positions follow the texel-centre rule, not stored


AXES = {a.name: a for a in (
    Axis("theta_i", True, (-HALF_PI, HALF_PI), "clamp", "rad",
         "θ_i = asin(ω_i·t): longitudinal angle of the direction toward the light"),
    Axis("theta_d", True, (-HALF_PI, HALF_PI), "clamp", "rad",
         "θ_d = (θ_o − θ_i)/2: half difference of the longitudinal angles of view and light"),
    Axis("phi", True, (-math.pi, math.pi), "repeat", "rad",
         "φ = φ_o − φ_i wrapped to [−π, π): azimuth of the view minus azimuth of the light"),
    Axis("v", True, (-1.0, 1.0), "clamp", "1",
         "v: position across the strip, offset from the yarn axis along b divided by the strip half-width"),
    Axis("v_tex", True, (-1.0, 1.0), "clamp", "1", "v on texture rows (texel centres, positions not stored)",
         store_samples=False),
    Axis("u_tex", True, (0.0, 1.0), "repeat", "1",
         "u = s/period on texture columns, s the rest arc length (texel centres, positions not stored)",
         store_samples=False),
    Axis("cos_theta_j", True, (0.0, 1.0), "clamp", "1", "cos θ_j, θ_j the longitudinal angle of the SRBF centre"),
    Axis("cos_theta_o", True, (0.0, 1.0), "clamp", "1", "cos θ_o, θ_o the longitudinal angle of the view"),
    Axis("cos_theta_j_minus_theta_o", True, (-1.0, 1.0), "clamp", "1", "cos(θ_j − θ_o)"),
    Axis("inv_lambda", True, (0.0, 2.0), "clamp", "1", "1/λ_j, λ_j the SRBF sharpness (λ ≥ 0.5)"),
    Axis("channel", False, None, None, "", "colour or vector channel"),
    Axis("variant", False, None, None, "", "flyaway texture variant 0, 1, 2"),
)}
WRAPS = ("clamp", "repeat")
# the on-disk axis name of the texture axes is plain "v"/"u"
_DISK_AXIS_NAME = {"v_tex": "v", "u_tex": "u"}


def cell_centres(lo: float, hi: float, n: int) -> np.ndarray:
    """Sample positions of an axis: the centres of n equal cells over [lo, hi] (the pack's only grid rule)."""
    return lo + (np.arange(n, dtype=np.float64) + 0.5) * ((hi - lo) / n)


# --- the table schema ---------------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class TableSpec:
    """One optional table. ``name`` is the dataset path below the root (``{k}``: mip level); ``shape`` holds ints
    and symbols, a symbol binds once per ``family`` (for mip levels: to level 0, level k has max(1, S >> k));
    ``channel_ranges``/``value_range`` are closed allowed ranges (None: unbounded); ``vector`` = number of
    leading channels that form a vector of length ≤ 1."""

    name: str
    family: str
    shape: tuple
    axes: tuple
    units: str
    description: str
    value_range: tuple = (None, None)
    channel_ranges: tuple | None = None
    vector: int = 0
    mip: bool = False
    axes_overridable: bool = False

    @property
    def base(self) -> str:
        return self.name[: -len("/mip{k}")] if self.mip else self.name


_DS = (
    ("a_f", "1", (0.0, None), "ā_f: average forward attenuation (hemispherical integral of f·cos over the front)"),
    ("a_b", "1", (0.0, None), "ā_b: average backward attenuation"),
    ("alpha_f", "rad", (None, None), "ᾱ_f: average longitudinal shift, forward scattering"),
    ("alpha_b", "rad", (None, None), "ᾱ_b: average longitudinal shift, backward scattering"),
    ("beta_f", "rad", (0.0, None), "β̄_f: average longitudinal width (standard deviation), forward"),
    ("beta_b", "rad", (0.0, None), "β̄_b: average longitudinal width (standard deviation), backward"),
    ("A_b", "1", (0.0, None), "Ā_b: average backscattering attenuation (Zinke eq. 14)"),
    ("Delta_b", "rad", (None, None), "Δ̄_b: average backscattering longitudinal shift (Zinke eq. 16)"),
    ("sigma_b", "rad", (0.0, None), "σ̄_b: average backscattering longitudinal width, std. dev. (Zinke eq. 17)"),
)
_UNIT_VEC = ((-1.0, 1.0),) * 3
_TANGENT = ((0.0, 1.0), (-1.0, 1.0), (-1.0, 1.0))

TABLES = (
    *(TableSpec(f"dual_scattering/{n}", "dual_scattering", ("N_theta", 3), ("theta_i", "channel"), u, d, value_range=r)
      for n, u, r, d in _DS),
    TableSpec("correction/xi_M", "correction", ("N_v", "N_theta", 3), ("v", "theta_d", "channel"), "1",
              "ξ_M(v, θ_d): longitudinal factor of the DS correction ξ = Ψ_*/Ψ_DS", value_range=(0.0, None)),
    TableSpec("correction/xi_N", "correction", ("N_v", "N_phi", 3), ("v", "phi", "channel"), "1",
              "ξ_N(v, φ): azimuthal factor of the DS correction", value_range=(0.0, None)),
    TableSpec("correction/xi", "correction", ("N_v", "N_theta", "N_phi", 3), ("v", "theta_d", "phi", "channel"), "1",
              "ξ(v, θ_d, φ) as baked, before factorization (since schema 1.1)", value_range=(0.0, None)),
    TableSpec("correction/xi_residual", "correction", (), (), "1",
              "relative RMS residual of ξ ≈ ξ_M ξ_N over the whole baked grid", value_range=(0.0, None)),
    TableSpec("correction/xi_residual_by_v", "correction", ("N_v",), ("v",), "1",
              "relative RMS residual of ξ ≈ ξ_M ξ_N at each v", value_range=(0.0, None)),
    TableSpec("shadowing/psi_GM", "shadowing", ("N_v", "N_theta", 3), ("v", "theta_i", "channel"), "1",
              "Ψ^Fiber_{G,M}(v, θ_i): longitudinal factor of fiber-level shadowing", value_range=(0.0, None)),
    TableSpec("shadowing/psi_GN", "shadowing", ("N_v", "N_phi", 3), ("v", "phi", "channel"), "1",
              "Ψ^Fiber_{G,N}(v, φ): azimuthal factor of fiber-level shadowing", value_range=(0.0, None)),
    TableSpec("shadowing/psi", "shadowing", ("N_v", "N_theta", "N_phi", 3), ("v", "theta_i", "phi", "channel"), "1",
              "Ψ^Fiber_G(v, θ_i, φ) as baked, before factorization (since schema 1.1)", value_range=(0.0, None)),
    TableSpec("shadowing/psi_residual", "shadowing", (), (), "1",
              "relative RMS residual of Ψ^Fiber_G ≈ Ψ_{G,M} Ψ_{G,N} over the whole baked grid",
              value_range=(0.0, None)),
    TableSpec("shadowing/psi_residual_by_v", "shadowing", ("N_v",), ("v",), "1",
              "relative RMS residual of the shadowing factorization at each v", value_range=(0.0, None)),
    TableSpec("textures/normal/mip{k}", "textures", ("H", "W", 3), ("v_tex", "u_tex", "channel"), "1",
              "coverage-premultiplied fiber normal in the strip frame (t, b, n)", channel_ranges=_UNIT_VEC,
              vector=3, mip=True),
    TableSpec("textures/tangent/mip{k}", "textures", ("H", "W", 3), ("v_tex", "u_tex", "channel"), "1",
              "coverage-premultiplied fiber tangent in the strip frame, sign with t-component ≥ 0",
              channel_ranges=_TANGENT, vector=3, mip=True),
    TableSpec("textures/ao/mip{k}", "textures", ("H", "W"), ("v_tex", "u_tex"), "1",
              "ambient visibility of the visible fibers (1 = unoccluded; 1 where coverage is 0)",
              value_range=(0.0, 1.0), mip=True),
    TableSpec("textures/coverage/mip{k}", "textures", ("H", "W"), ("v_tex", "u_tex"), "1",
              "fraction of the texel covered by regular fibers", value_range=(0.0, 1.0), mip=True),
    TableSpec("textures/flyaway/mip{k}", "flyaway", (3, "H", "W", 4), ("variant", "v_tex", "u_tex", "channel"), "1",
              "three seamless flyaway textures: RGB coverage-premultiplied tangent, A coverage",
              channel_ranges=(*_TANGENT, (0.0, 1.0)), vector=3, mip=True),
    TableSpec("environment/I_M_TT_D", "environment", ("N_a", "N_b", "N_c", "N_d", 3),
              ("cos_theta_j", "cos_theta_o", "cos_theta_j_minus_theta_o", "inv_lambda", "channel"), "1",
              "I_M^{TT,D} = ∫ G_j(ω_i) (f_TT + f_D)(ω_i, ω_o) cos θ_i dω_i, the TT and D lobes of I_M (the consumer "
              "integrates the R lobe, §9), over a self-described 4-D parameterisation",
              value_range=(0.0, None), axes_overridable=True),
)
_BY_NAME = {t.name: t for t in TABLES}
_MIP_RE = re.compile(r"^(?P<base>.+)/mip(?P<k>0|[1-9][0-9]?)$")


def resolve_table(name: str):
    """(TableSpec, mip level or None) for a table name such as ``correction/xi_M`` or ``textures/ao/mip2``;
    None if the name is not in the schema."""
    if name in _BY_NAME and not _BY_NAME[name].mip:
        return _BY_NAME[name], None
    m = _MIP_RE.match(name)
    if m and int(m["k"]) < MAX_MIP_LEVELS:
        spec = _BY_NAME.get(f"{m['base']}/mip{{k}}")
        if spec is not None:
            return spec, int(m["k"])
    return None


def _known_names_hint() -> str:
    return ", ".join(t.name.replace("{k}", "K") for t in TABLES)


# --- the attribute schema -----------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class AttrSpec:
    """One required attribute of a group ("" = root). ``kind`` decides the check and the on-disk encoding."""

    group: str
    name: str
    kind: str  # const, version, str, units, int, float, rgb, angle, toml, json_object, json_timings, json_counts,
    #            isotime
    units: str
    lo: float | None
    hi: float | None
    description: str
    value: object = None  # for kind "const"


ATTRS = (
    AttrSpec("", "format", "const", "", None, None, "file format name", FORMAT_NAME),
    AttrSpec("", "schema_version", "version", "", None, None, '"major.minor"; unknown major: refuse'),
    AttrSpec("yarn", "name", "str", "", None, None, "yarn type name"),
    AttrSpec("yarn", "units", "units", "", None, None, f"length unit of every length in the pack "
             f"({', '.join(LENGTH_UNITS)}; presets: cm)"),
    AttrSpec("yarn", "radius", "float", "length", 0.0, None, "outer radius of the regular fibers (> 0)"),
    AttrSpec("yarn", "period", "float", "length", 0.0, None,
             "length of one ply-twist period along the yarn: the period of every texture (> 0)"),
    AttrSpec("yarn", "plies", "int", "", 1, None, "number of plies K (≥ 1)"),
    AttrSpec("provenance", "yarn_spec_toml", "toml", "", None, None, "the yarn spec the pack was baked from (TOML)"),
    AttrSpec("provenance", "bake_settings", "json_object", "", None, None, "bake settings (JSON object)"),
    AttrSpec("provenance", "seed", "int", "", 0, 2**63 - 1, "random seed of the bake (≥ 0)"),
    AttrSpec("provenance", "code_version", "str", "", None, None, "version of the code that baked the pack"),
    AttrSpec("provenance", "created", "isotime", "", None, None, "creation time, ISO 8601"),
    AttrSpec("provenance", "timings", "json_timings", "s", None, None, "JSON object: stage → seconds"),
    AttrSpec("provenance", "sample_counts", "json_counts", "", None, None,
             "JSON object: table → counts (non-negative integers, possibly nested)"),
    AttrSpec("fiber_bcsdf", "r_color", "rgb", "1", 0.0, 1.0, "A_R: R lobe colour, linear RGB"),
    AttrSpec("fiber_bcsdf", "tt_color", "rgb", "1", 0.0, 1.0, "A_TT: TT lobe colour, linear RGB"),
    AttrSpec("fiber_bcsdf", "d_color", "rgb", "1", 0.0, 1.0, "A_D: D (diffuse) lobe colour, linear RGB"),
    AttrSpec("fiber_bcsdf", "beta_r", "angle", "rad", 0.0, HALF_PI, "β_R: longitudinal width of R (> 0)"),
    AttrSpec("fiber_bcsdf", "beta_tt", "angle", "rad", 0.0, HALF_PI, "β_TT: longitudinal width of TT (> 0)"),
    AttrSpec("fiber_bcsdf", "gamma_tt", "angle", "rad", 0.0, math.pi, "γ_TT: azimuthal width of TT (> 0)"),
    AttrSpec("fiber_bcsdf", "alpha_r", "angle", "rad", -HALF_PI, HALF_PI, "α_R: longitudinal shift of R"),
    AttrSpec("fiber_bcsdf", "alpha_tt", "angle", "rad", -HALF_PI, HALF_PI, "α_TT: longitudinal shift of TT"),
)
GROUPS = ("yarn", "provenance", "fiber_bcsdf")
_POSITIVE = {("yarn", "radius"), ("yarn", "period"), ("fiber_bcsdf", "beta_r"), ("fiber_bcsdf", "beta_tt"),
             ("fiber_bcsdf", "gamma_tt")}
# attributes a writer may not set through table_attrs (the writer owns them)
_RESERVED_TABLE_ATTRS = {"units", "error_estimate", "axes", "description", "error_of"}


# --- small helpers ------------------------------------------------------------------------------------------------

def _py(value):
    """An attribute value as plain Python (str for strings, list[str] for string arrays, ndarray for numbers)."""
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    if isinstance(value, np.ndarray):
        if value.dtype.kind in "OSU":
            return [_py(v) for v in value.tolist()]
        return value
    if isinstance(value, np.generic):
        return value.item()
    return value


def _is_int(v) -> bool:
    return isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_))


def _is_real(v) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_))


def _short(value, limit=60) -> str:
    text = repr(value.tolist() if isinstance(value, np.ndarray) else value)
    text = " ".join(text.split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _json_leaves_ok(obj, leaf_ok) -> bool:
    if isinstance(obj, dict):
        return all(isinstance(k, str) and _json_leaves_ok(v, leaf_ok) for k, v in obj.items())
    if isinstance(obj, list):
        return all(_json_leaves_ok(v, leaf_ok) for v in obj)
    return leaf_ok(obj)


def _attr_problem(spec: AttrSpec, value, on_disk: bool):
    """Check one attribute. Returns (normalized Python value, problem text or None). ``value`` is what the writer
    was given (on_disk=False; JSON kinds may be dict or str) or what was read (on_disk=True)."""
    value = _py(value)
    k = spec.kind
    if k == "const":
        return value, None if value == spec.value else f"is {_short(value)}, expected {spec.value!r}"
    if k == "version":
        if not isinstance(value, str) or not re.fullmatch(r"[0-9]+\.[0-9]+", value):
            return value, f"is {_short(value)}, expected a \"major.minor\" string such as {SCHEMA_VERSION!r}"
        return value, None
    if k in ("str", "units"):
        if not isinstance(value, str) or not value.strip():
            return value, f"is {_short(value)}, expected a non-empty string"
        if k == "units" and value not in LENGTH_UNITS:
            return value, f"is {value!r}, expected one of {', '.join(LENGTH_UNITS)}"
        return value, None
    if k == "int":
        if not _is_int(value) or (spec.lo is not None and value < spec.lo) or (spec.hi is not None and value > spec.hi):
            rng = f"≥ {spec.lo}" if spec.hi is None else f"in [{spec.lo}, {spec.hi}]"
            return value, f"is {_short(value)}, expected an integer {rng}"
        return int(value), None
    if k in ("float", "angle"):
        positive = (spec.group, spec.name) in _POSITIVE
        ok = _is_real(value) and math.isfinite(float(value))
        if ok:
            v = float(value)
            ok = (spec.lo is None or (v > spec.lo if positive else v >= spec.lo)) and (spec.hi is None or v <= spec.hi)
        if not ok:
            lo = "" if spec.lo is None else ("(" if positive else "[") + f"{spec.lo:g}"
            hi = "∞)" if spec.hi is None else f"{spec.hi:g}]"
            unit = f" {spec.units}" if spec.units else ""
            what = "an angle in radians " if k == "angle" else "a finite number "
            return value, f"is {_short(value)}, expected {what}in {lo}, {hi}{unit}"
        return float(value), None
    if k == "rgb":
        arr = np.asarray(value) if isinstance(value, (list, tuple, np.ndarray)) else None
        if (arr is None or arr.shape != (3,) or arr.dtype.kind not in "iuf" or not np.all(np.isfinite(arr))
                or np.any(arr < spec.lo) or np.any(arr > spec.hi)):
            return value, f"is {_short(value)}, expected 3 numbers (linear RGB) in [{spec.lo:g}, {spec.hi:g}]"
        return [float(x) for x in arr], None
    if k == "toml":
        if not isinstance(value, str):
            return value, f"is {_short(value)}, expected TOML text"
        try:
            tomllib.loads(value)
        except tomllib.TOMLDecodeError as exc:
            return value, f"is not valid TOML ({' '.join(str(exc).split())})"
        return value, None
    if k == "isotime":
        try:
            datetime.datetime.fromisoformat(value)
        except (TypeError, ValueError):
            return value, f"is {_short(value)}, expected an ISO 8601 time such as '2026-01-31T12:00:00+00:00'"
        return value, None
    if k.startswith("json_"):
        obj = value
        if isinstance(value, str):
            try:
                obj = json.loads(value)
            except ValueError as exc:
                return value, f"is not valid JSON ({exc})"
        elif on_disk:
            return value, f"is {_short(value)}, expected JSON text"
        if not isinstance(obj, dict):
            return value, f"is {_short(value)}, expected a JSON object"
        try:
            json.dumps(obj, allow_nan=False)
        except (TypeError, ValueError) as exc:
            return value, f"is not JSON-serializable ({exc})"
        if k == "json_timings" and not _json_leaves_ok(
                obj, lambda x: _is_real(x) and math.isfinite(x) and x >= 0):
            return value, f"is {_short(obj)}, expected an object of stage → seconds (finite, ≥ 0)"
        if k == "json_counts" and not _json_leaves_ok(obj, lambda x: _is_int(x) and x >= 0):
            return value, f"is {_short(obj)}, expected an object of table → counts (integers ≥ 0, may nest)"
        return obj, None
    raise AssertionError(k)  # pragma: no cover


def _encode_attr(spec: AttrSpec, value):
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


def _extra_attr_problem(value):
    """Extra (non-schema) attributes in yarn/provenance/fiber_bcsdf/tables: strings, finite numbers, finite arrays."""
    value = _py(value)
    if isinstance(value, str):
        return value, None
    if _is_real(value) and math.isfinite(float(value)):
        return value, None
    if isinstance(value, (list, tuple, np.ndarray)):
        if all(isinstance(x, str) for x in value) and len(value) > 0:
            return list(value), None
        arr = np.asarray(value)
        if arr.dtype.kind in "iuf" and arr.ndim == 1 and np.all(np.isfinite(arr)):
            return arr, None
    return value, f"is {_short(value)}, expected a string, a finite number or a 1-D finite array"


def _encode_extra(value):
    if isinstance(value, list) and value and all(isinstance(x, str) for x in value):
        return np.array(value, dtype=h5py.string_dtype())
    return value


# --- table checks (shared by writer, reader, validator) ------------------------------------------------------------

def _axis_attrs(spec: TableSpec, shape, override=None) -> dict:
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
        names.append(_DISK_AXIS_NAME.get(axis_name, axis_name))
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


def _table_meta_problems(name: str, spec: TableSpec, shape: tuple, dtype, attrs: dict) -> list[str]:
    """Attribute and dtype problems of one table (metadata only, no data read). ``attrs`` as plain Python."""
    probs = []
    if np.dtype(dtype) != TABLE_DTYPE:
        probs.append(f"{name}: dtype is {np.dtype(dtype)}, expected float32 (little-endian)")
    units = attrs.get("units")
    if units != spec.units:
        probs.append(f"{name}: attr units is {'missing' if units is None else _short(units)}, expected {spec.units!r}")
    est = attrs.get("error_estimate")
    if est is None:
        probs.append(f"{name}: attr error_estimate is missing, expected a finite number ≥ 0 (every table needs an "
                     f"error estimate)")
    elif not (_is_real(est) and math.isfinite(float(est)) and float(est) >= 0):
        probs.append(f"{name}: attr error_estimate is {_short(est)}, expected a finite number ≥ 0")
    for key in ("error_kind", "error_statistic"):
        v = attrs.get(key)
        if not isinstance(v, str) or not v.strip():
            probs.append(f"{name}: attr {key} is {'missing' if v is None else _short(v)}, expected a non-empty "
                         f"string")
    if spec.mip:
        hw = attrs.get("half_width")
        if not (_is_real(hw) and math.isfinite(float(hw)) and float(hw) > 0):
            probs.append(f"{name}: attr half_width is {'missing' if hw is None else _short(hw)}, expected the strip "
                         f"half-width in yarn units (> 0)")
    axes = attrs.get("axes")
    ndim = len(spec.shape)
    if ndim == 0:
        return probs
    if not (isinstance(axes, list) and len(axes) == ndim and all(isinstance(a, str) and a for a in axes)):
        probs.append(f"{name}: attr axes is {_short(axes)}, expected {ndim} axis names")
        return probs
    if len(shape) != ndim:
        return probs  # reported by _shape_problems
    if len(set(axes)) != len(axes):
        probs.append(f"{name}: attr axes {axes} repeats a name, expected distinct axis names")
    for i, axis_name in enumerate(spec.axes):
        ax = AXES[axis_name]
        disk_name = _DISK_AXIS_NAME.get(axis_name, axis_name)
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
            probs.append(f"{name}: attr axis{i}_range is {_short(rng)}, expected [lo, hi] finite with lo < hi")
            continue
        if not free and not np.allclose(rng, ax.range, rtol=0, atol=1e-12):
            probs.append(f"{name}: attr axis{i}_range is {rng.tolist()}, expected {list(ax.range)} ({axis_name})")
        wrap = attrs.get(f"axis{i}_wrap")
        expected_wrap = WRAPS if free else (ax.wrap,)
        if wrap not in expected_wrap:
            probs.append(f"{name}: attr axis{i}_wrap is {_short(wrap)}, expected "
                         f"{' or '.join(map(repr, expected_wrap))}")
        au = attrs.get(f"axis{i}_units")
        if not isinstance(au, str) or (not free and au != ax.units):
            want_units = repr(ax.units) if not free else "a string"
            probs.append(f"{name}: attr axis{i}_units is {_short(au)}, expected {want_units}")
        if free:
            d = attrs.get(f"axis{i}_definition")
            if not isinstance(d, str) or not d.strip():
                probs.append(f"{name}: attr axis{i}_definition is {_short(d)}, expected a non-empty description of "
                             f"the axis variable")
        samples = attrs.get(f"axis{i}_samples")
        if ax.store_samples or free:
            want = cell_centres(float(rng[0]), float(rng[1]), shape[i])
            if not (isinstance(samples, np.ndarray) and samples.shape == want.shape and samples.dtype.kind == "f"
                    and np.allclose(samples, want, rtol=1e-9, atol=1e-12)):
                probs.append(f"{name}: attr axis{i}_samples is {_short(samples)}, expected the {shape[i]} cell centres "
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


def _shape_problems(entries) -> list[str]:
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


def _numeric_problems(name: str, spec: TableSpec, arr: np.ndarray, what: str = "") -> list[str]:
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


def _stderr_problems(name: str, spec: TableSpec, table_shape, err: np.ndarray, estimate) -> list[str]:
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
    if (_is_real(estimate) and math.isfinite(float(estimate))
            and not math.isclose(float(estimate), mx, rel_tol=1e-6, abs_tol=1e-30)):
        return [f"{name}: attr error_estimate is {float(estimate):g}, expected the maximum of {label} ({mx:g})"]
    return []


# --- the in-memory pack -------------------------------------------------------------------------------------------

@dataclasses.dataclass
class AxisInfo:
    name: str
    size: int
    range: tuple | None = None  # (lo, hi) for sampled axes; samples are cell centres
    wrap: str | None = None
    units: str = ""
    definition: str = ""

    @property
    def samples(self):
        return None if self.range is None else cell_centres(self.range[0], self.range[1], self.size)


@dataclasses.dataclass
class TableInfo:
    """Metadata of one table present in a pack (read without touching its data)."""

    name: str
    shape: tuple
    units: str
    axes: list
    error_estimate: float
    error_kind: str
    error_statistic: str
    has_stderr: bool
    attrs: dict


@dataclasses.dataclass
class AssetPack:
    """A read pack. ``tables``/``stderr`` hold only the datasets asked for; ``info`` describes every table."""

    path: str
    schema_version: str
    yarn: dict
    provenance: dict
    fiber_bcsdf: dict
    info: dict
    tables: dict
    stderr: dict

    def mip_chain(self, base: str) -> list:
        """The loaded mip levels of texture ``base`` (e.g. ``textures/normal``), level 0 first."""
        out = []
        while f"{base}/mip{len(out)}" in self.tables:
            out.append(self.tables[f"{base}/mip{len(out)}"])
        return out


# --- writer -------------------------------------------------------------------------------------------------------

def _raise(path, probs):
    if probs:
        more = f" (and {len(probs) - 1} more problem(s))" if len(probs) > 1 else ""
        raise FormatError(f"{path}: {probs[0]}{more}")


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
        value, prob = _attr_problem(spec, given.pop(spec.name), on_disk=False)
        if prob:
            raise FormatError(f"{path}: {group}.{spec.name} {prob}")
        out[spec.name] = _encode_attr(spec, value)
    for key, value in given.items():
        value, prob = _extra_attr_problem(value)
        if prob or not isinstance(key, str) or not key:
            raise FormatError(f"{path}: {group}.{key} {prob or 'has an invalid name'}")
        out[key] = _encode_extra(value)
    return out


def _check_axes_override(path, name, spec, axes) -> dict:
    sampled = [i for i, a in enumerate(spec.axes) if AXES[a].sampled]
    if not isinstance(axes, (list, tuple)) or len(axes) != len(sampled):
        raise FormatError(f"{path}: table_attrs[{name!r}]['axes'] is {_short(axes)}, expected a list of "
                          f"{len(sampled)} dicts with name, range, wrap, units, definition")
    override = {}
    for i, desc in zip(sampled, axes):
        if not isinstance(desc, dict) or not {"name", "range", "definition"} <= set(desc) or not set(desc) <= {
                "name", "range", "wrap", "units", "definition"}:
            raise FormatError(f"{path}: table_attrs[{name!r}]['axes'][{i}] is {_short(desc)}, expected a dict with "
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
            raise FormatError(f"{path}: table {name!r} is not in the schema (known: {_known_names_hint()})")
        spec, level = resolved
        arr = np.asarray(value)
        if arr.dtype.kind != "f":
            raise FormatError(f"{path}: {name}: dtype is {arr.dtype}, expected a real floating-point array "
                              f"(stored as float32)")
        with np.errstate(over="ignore", invalid="ignore"):
            data = np.array(arr, dtype=TABLE_DTYPE, order="C")
        entries.append((name, spec, level, data.shape))
        _raise(path, _shape_problems([(name, spec, None, data.shape)]))  # rank and fixed dimensions
        if np.all(np.isfinite(arr)) and not np.all(np.isfinite(data)):
            raise FormatError(f"{path}: {name}: values overflow float32 (max |x| = {float(np.abs(arr).max()):g}), "
                              f"expected |x| < 3.4e38")
        _raise(path, _numeric_problems(name, spec, data))
        if name not in errors:
            raise FormatError(f"{path}: {name}: no error estimate (errors[{name!r}] is missing; every table needs "
                              f"a scalar or per-entry error)")
        err = errors[name]
        stderr = None
        extra = dict(table_attrs.get(name) or {})
        if np.ndim(err) == 0:
            if not _is_real(err) or not math.isfinite(float(err)) or float(err) < 0:
                raise FormatError(f"{path}: errors[{name!r}] is {_short(err)}, expected a finite number ≥ 0")
            estimate = float(err)
            statistic = extra.pop("error_statistic", "max")
        else:
            e = np.asarray(err)
            if e.dtype.kind not in "f":
                raise FormatError(f"{path}: errors[{name!r}] dtype is {e.dtype}, expected floats")
            with np.errstate(over="ignore", invalid="ignore"):
                stderr = np.array(e, dtype=TABLE_DTYPE, order="C")
            _raise(path, _stderr_problems(name, spec, data.shape, stderr, None))
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
            value, prob = _extra_attr_problem(value)
            if prob:
                raise FormatError(f"{path}: table_attrs[{name!r}][{key!r}] {prob}")
            attrs[key] = value
        if len(data.shape) == len(spec.shape):
            try:
                attrs.update(_axis_attrs(spec, data.shape, override))
            except (TypeError, ValueError) as exc:
                raise FormatError(f"{path}: table_attrs[{name!r}]['axes'] is malformed ({exc})") from None
        planned[name] = (spec, level, data, stderr, attrs)

    _raise(path, _shape_problems(entries))
    for name, (spec, level, data, stderr, attrs) in planned.items():
        _raise(path, _table_meta_problems(name, spec, data.shape, data.dtype, attrs))

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
        ds.attrs[key] = _encode_extra(value)


# --- reader -------------------------------------------------------------------------------------------------------

def _version(f, path, probs):
    """(major, minor) of an open pack, or None after recording why the file is not readable as a pack."""
    fmt = _py(f.attrs.get("format"))
    if fmt != FORMAT_NAME:
        probs.append(f"root attr format is {'missing' if fmt is None else _short(fmt)}, expected {FORMAT_NAME!r}")
        return None
    spec = next(a for a in ATTRS if a.name == "schema_version")
    raw = f.attrs.get("schema_version")
    if raw is None:
        probs.append(f"root attr schema_version is missing, expected {SCHEMA_VERSION!r}")
        return None
    value, prob = _attr_problem(spec, raw, on_disk=True)
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
        attrs = {k: node.attrs[k] for k in node.attrs}
        values = {}
        for spec in ATTRS:
            if spec.group != group:
                continue
            if spec.name not in attrs:
                probs.append(f"{group}.{spec.name} is missing, expected {spec.description}")
                continue
            value, prob = _attr_problem(spec, attrs.pop(spec.name), on_disk=True)
            if prob:
                probs.append(f"{group}.{spec.name} {prob}")
            values[spec.name] = value
        for key, value in attrs.items():
            values[key] = _py(value)
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
    attrs = {k: _py(ds.attrs[k]) for k in ds.attrs}
    probs.extend(_table_meta_problems(name, spec, ds.shape, ds.dtype, attrs))
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
                     error_estimate=float(est) if _is_real(est) else float("nan"),
                     error_kind=str(attrs.get("error_kind", "")), error_statistic=str(attrs.get("error_statistic", "")),
                     has_stderr=stderr_ds is not None, attrs=attrs)


def _load(name, spec, ds, stderr_ds, info, probs):
    data = ds[()]
    data = np.asarray(data)
    probs.extend(_numeric_problems(name, spec, data.astype(TABLE_DTYPE, copy=False)
                                   if data.dtype.kind == "f" else data.astype(np.float64)))
    err = None
    if stderr_ds is not None:
        err = np.asarray(stderr_ds[()])
        probs.extend(_stderr_problems(name, spec, data.shape, err, info.error_estimate))
    return data, err


def _open(path):
    path = Path(path)
    if not path.is_file():
        raise FormatError(f"{path}: no such file, expected an asset pack (.h5)")
    try:
        with open(path, "rb") as fh:
            magic = fh.read(8)
    except OSError as exc:
        raise FormatError(f"{path}: cannot read ({exc.__class__.__name__}: {exc})") from None
    if magic != HDF5_MAGIC:
        raise FormatError(f"{path}: not an HDF5 file (first bytes {magic!r}), expected an asset pack")
    try:
        return h5py.File(path, "r")
    except OSError as exc:
        raise FormatError(f"{path}: unreadable HDF5 (truncated or corrupt: {' '.join(str(exc).split())})") from None


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
        probs.extend(_shape_problems([(n, s, lvl, ds.shape) for n, (s, lvl, ds, _) in found.items()]))
        info = {n: _table_info(n, s, ds, e, probs) for n, (s, lvl, ds, e) in found.items()}
        if tables is None:
            wanted = list(found)
        else:
            wanted = []
            for name in tables:
                if resolve_table(name) is None:
                    probs.append(f"table {name!r} is not in the schema (known: {_known_names_hint()})")
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
        return AssetPack(path=str(path), schema_version=str(_py(f.attrs["schema_version"])),
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
    _raise(path, probs)
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
    try:
        with open(path, "rb") as fh:
            if fh.read(8) != HDF5_MAGIC:
                return False
        with h5py.File(path, "r") as f:
            return _py(f.attrs.get("format")) == FORMAT_NAME
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


# --- documentation ------------------------------------------------------------------------------------------------

def _fmt_angle(x: float) -> str:
    for text, val in (("π/2", HALF_PI), ("π", math.pi)):
        if math.isclose(abs(x), val):
            return ("−" if x < 0 else "") + text
    return f"{x:g}"


def schema_markdown() -> str:
    """The member tables of ASSET_PACK.md, generated from ATTRS and TABLES (a test keeps the two equal)."""
    rows = ["| group | attribute | type | units | meaning |", "|---|---|---|---|---|"]
    for a in ATTRS:
        rows.append(f"| `/{a.group}` | `{a.name}` | {a.kind} | {a.units} | {a.description} |")
    rows += ["", "| dataset | shape | axes | units | allowed values | meaning |", "|---|---|---|---|---|---|"]
    for t in TABLES:
        shape = "(" + ", ".join(map(str, t.shape)) + ("," if len(t.shape) == 1 else "") + ")"
        axes = ", ".join(_DISK_AXIS_NAME.get(a, a) for a in t.axes) or "—"
        if t.channel_ranges:
            allowed = "channels " + ", ".join(f"[{lo:g}, {hi:g}]" for lo, hi in t.channel_ranges)
        else:
            lo, hi = t.value_range
            allowed = "finite" if lo is None and hi is None else \
                f"{'(−∞' if lo is None else f'[{lo:g}'}, {'∞)' if hi is None else f'{hi:g}]'}"
        if t.vector:
            allowed += f"; ‖ch 0..{t.vector - 1}‖ ≤ 1"
        rows.append(f"| `{t.name}` | {shape} | {axes} | {t.units} | {allowed} | {t.description} |")
    rows += ["", "| axis | range | wrap | units | meaning |", "|---|---|---|---|---|"]
    for a in AXES.values():
        if a.sampled:
            rng = f"[{_fmt_angle(a.range[0])}, {_fmt_angle(a.range[1])}]"
            rows.append(f"| `{_DISK_AXIS_NAME.get(a.name, a.name)}` | {rng} | {a.wrap} | {a.units} | {a.definition} |")
        else:
            rows.append(f"| `{a.name}` | index | — | — | {a.definition} |")
    return "\n".join(rows)
