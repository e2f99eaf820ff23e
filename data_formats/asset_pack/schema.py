"""Asset-pack schema: the format constants, the table axes (``AXES``, ``IM_AXES``), the optional tables (``TABLES``,
``resolve_table``) and the required attributes (``ATTRS``). These tables are the single schema: the writer, the
reader, the validator (``checks``) and the generated part of ``ASSET_PACK.md`` (``spec_markdown``) read them."""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np

from ..conventions import HALF_PI, LENGTH_UNITS, PHI_RANGE, THETA_RANGE

FORMAT_NAME = "knit-asset-pack"
SCHEMA_VERSION = "2.7"
SCHEMA_MAJOR, SCHEMA_MINOR = (int(p) for p in SCHEMA_VERSION.split("."))
# the closure stage version whose closed ξ (correction/xi_view, xi_closed) closes on knit's current renderer; each
# closed table carries the version that baked it (attribute closure_version, ASSET_PACK.md §6) and knit's renderer
# warns about an older one (a pack closed before version 4 has none). 5: paths of MAX_DEPTH (32) events, as the
# references', not 16; a part's bin that fails the per-row test takes its angle bin's v-summed ratio (ASSET_PACK.md §6)
CLOSURE_STAGE_VERSION = 5
TABLE_DTYPE = np.dtype("<f4")
MAX_MIP_LEVELS = 16
COMPRESS_BYTES = 1 << 16  # datasets at least this large are stored gzip(4)+shuffle
STDERR_SUFFIX = "_stderr"
DEFAULT_ERROR_KIND = "standard error of the mean over independent sample batches"


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
    Axis("theta_i", True, THETA_RANGE, "clamp", "rad",
         "θ_i = asin(ω_i·t): longitudinal angle of the direction toward the light"),
    Axis("theta_d", True, THETA_RANGE, "clamp", "rad",
         "θ_d = (θ_o − θ_i)/2: half difference of the longitudinal angles of view and light"),
    Axis("phi", True, PHI_RANGE, "repeat", "rad",
         "φ = φ_o − φ_i wrapped to [−π, π): azimuth of the view minus azimuth of the light"),
    Axis("v", True, (-1.0, 1.0), "clamp", "1",
         "v: position across the strip, offset from the yarn axis along b divided by the strip half-width"),
    Axis("v_tex", True, (-1.0, 1.0), "clamp", "1", "v on texture rows (texel centres, positions not stored)",
         store_samples=False),
    Axis("u_tex", True, (0.0, 1.0), "repeat", "1",
         "u = s/period on texture columns, s the rest arc length (texel centres, positions not stored)",
         store_samples=False),
    Axis("theta_o", True, THETA_RANGE, "clamp", "rad",
         "θ_o = asin(ω_o·t), longitudinal angle of the view (t: the fiber tangent for I_M, the yarn tangent for "
         "the correction tables, §3)"),
    Axis("theta_j", True, THETA_RANGE, "clamp", "rad",
         "θ_j = asin(ω_j·t), longitudinal angle of the SRBF centre against the fiber tangent"),
    Axis("abs_phi_j_minus_phi_o", True, (0.0, math.pi), "clamp", "rad",
         "|φ_j − φ_o| wrapped into [0, π]: azimuth of the SRBF centre minus azimuth of the view "
         "(I_M is even in it because f is even in φ)"),
    Axis("log10_lambda", True, (math.log10(0.5), 4.0), "clamp", "1", "log10 λ_j, λ_j the SRBF sharpness"),
    Axis("colour_scale", True, (-1.0 / 32.0, 33.0 / 32.0), "clamp", "1",
         "k: the factor on the fiber's lobe albedos A_R, A_TT, A_D in one channel (a scene colour's channel); 17 "
         "cells put the samples at k = 0, 1/16, …, 1"),
    Axis("log2_colour_scale", True, (-3.5, -0.5), "clamp", "1",
         "log2 k, k the factor on the fiber's lobe albedos in one channel (as colour_scale); 3 cells put the samples "
         "at k = 1/8, 1/4, 1/2 (k = 1 is the white yarn's table)"),
    Axis("channel", False, None, None, "", "colour or vector channel"),
    Axis("variant", False, None, None, "", "flyaway texture variant 0, 1, 2"),
)}
# the sampled axes of the I_M table, in order: the schema's default and knitbake's parameterisation
# (``knitrun.shading.im_lookup``); a baker may state another (``TableSpec.axes_overridable``, ASSET_PACK.md §9)
IM_AXES = ("theta_o", "theta_j", "abs_phi_j_minus_phi_o", "log10_lambda")
WRAPS = ("clamp", "repeat")
# the on-disk axis name of the texture axes is plain "v"/"u" (used by the checks and the generated spec)
DISK_AXIS_NAME = {"v_tex": "v", "u_tex": "u"}


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
    TableSpec("correction/radiance", "correction", ("N_v", "N_theta", "N_phi", 3), ("v", "theta_d", "phi", "channel"),
              "1", "Ψ_*(v, θ_d, φ): the path-traced radiance per unit irradiance that ξ closes on, mean over the bin's "
              "pixels of the bake's straight yarn (since schema 2.3, §6)", value_range=(0.0, None)),
    TableSpec("correction/xi_closed", "correction", ("N_v", "N_theta", "N_phi", 3),
              ("v", "theta_d", "phi", "channel"), "1",
              "ξ closed on the strip renderer of SHADING.md: the factor with which it reproduces correction/radiance "
              "at the bin centres (since schema 2.3, §6)", value_range=(0.0, None)),
    TableSpec("correction/radiance_view", "correction", ("N_v", "N_theta", "N_theta", "N_phi", 3),
              ("v", "theta_i", "theta_o", "phi", "channel"), "1",
              "Ψ_*(v, θ_i, θ_o, φ): the path-traced radiance per unit irradiance of the bake's straight yarn seen "
              "from θ_o and lit from (θ_i, φ), mean over the bin's pixels, that correction/xi_view closes on (since "
              "schema 2.4, §6)", value_range=(0.0, None)),
    TableSpec("correction/xi_view", "correction", ("N_v", "N_theta", "N_theta", "N_phi", 3),
              ("v", "theta_i", "theta_o", "phi", "channel"), "1",
              "ξ closed on the strip renderer of SHADING.md at every view: the factor with which it reproduces "
              "correction/radiance_view at the bin centres (since schema 2.4, §6)", value_range=(0.0, None)),
    TableSpec("correction/radiance_view_ss", "correction", ("N_v", "N_theta", "N_theta", "N_phi", 3),
              ("v", "theta_i", "theta_o", "phi", "channel"), "1",
              "the single scattering of correction/radiance_view: paths of one scattering event (since schema 2.5, "
              "§6)", value_range=(0.0, None)),
    TableSpec("correction/xi_view_ss", "correction", ("N_v", "N_theta", "N_theta", "N_phi", 3),
              ("v", "theta_i", "theta_o", "phi", "channel"), "1",
              "ξ of single scattering, closed apart: the renderer's single scattering reproduces "
              "correction/radiance_view_ss at the bin centres (since schema 2.5, §6)", value_range=(0.0, None)),
    TableSpec("correction/xi_view_ms", "correction", ("N_v", "N_theta", "N_theta", "N_phi", 3),
              ("v", "theta_i", "theta_o", "phi", "channel"), "1",
              "ξ of multiple scattering, closed apart: the rest reproduces correction/radiance_view − "
              "correction/radiance_view_ss (since schema 2.5, §6)", value_range=(0.0, None)),
    TableSpec("correction/xi_view_ms_by_colour", "correction", ("N_kl", "N_v", "N_theta", "N_theta", "N_phi", 3),
              ("log2_colour_scale", "v", "theta_i", "theta_o", "phi", "channel"), "1",
              "correction/xi_view_ms closed on the yarn whose fibers' lobe albedos are scaled by k: channel c at k is "
              "the ξ of multiple scattering, in that channel, of the yarn drawn in a colour whose channel c is k (k < "
              "1; at k = 1 it is correction/xi_view_ms) (since schema 2.7, §6)", value_range=(0.0, None)),
    TableSpec("correction/xi_closed_ss", "correction", ("N_v", "N_theta", "N_phi", 3),
              ("v", "theta_d", "phi", "channel"), "1",
              "the diagonal θ_o = −θ_i of correction/xi_view_ss (since schema 2.5, §6)", value_range=(0.0, None)),
    TableSpec("correction/xi_closed_ms", "correction", ("N_v", "N_theta", "N_phi", 3),
              ("v", "theta_d", "phi", "channel"), "1",
              "the diagonal θ_o = −θ_i of correction/xi_view_ms (since schema 2.5, §6)", value_range=(0.0, None)),
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
    TableSpec("interreflection/albedo", "interreflection", (3,), ("channel",), "1",
              "ρ_Y: the yarn's hull albedo, mean radiance leaving the yarn tube under a uniform environment of "
              "radiance 1 (since schema 2.1, §10)", value_range=(0.0, 1.0)),
    TableSpec("interreflection/transmittance", "interreflection", (3,), ("channel",), "1",
              "T_Y: the yarn tube's transmittance, mean radiance leaving the tube toward a camera when only the "
              "hemisphere behind the yarn has radiance 1 (since schema 2.2, §10)", value_range=(0.0, 1.0)),
    TableSpec("interreflection/albedo_by_colour", "interreflection", ("N_k", 3), ("colour_scale", "channel"), "1",
              "ρ_Y of the yarn whose fibers' lobe albedos are scaled by k: channel c at k is the hull albedo, in that "
              "channel, of the yarn drawn in a colour whose channel c is k (since schema 2.6, §10)",
              value_range=(0.0, 1.0)),
    TableSpec("interreflection/transmittance_by_colour", "interreflection", ("N_k", 3), ("colour_scale", "channel"),
              "1", "T_Y of the yarn whose fibers' lobe albedos are scaled by k, as albedo_by_colour (since schema "
              "2.6, §10)", value_range=(0.0, 1.0)),
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
              (*IM_AXES, "channel"), "1",
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


def known_names_hint() -> str:
    """The schema's table names for an error message (mip levels written as ``mipK``)."""
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
# the float/angle attributes that must be > lo, not ≥ lo (checked by ``checks.attr_problem``)
POSITIVE = {("yarn", "radius"), ("yarn", "period"), ("fiber_bcsdf", "beta_r"), ("fiber_bcsdf", "beta_tt"),
            ("fiber_bcsdf", "gamma_tt")}
