"""Test data and builders shared by several test modules (fixtures are in ``conftest.py``, the χ² test in
``chi2.py``): tiny bake settings, an asset pack's attribute groups and a pack with every table, the BCSDF of a
rough fiber for the I_M tests, scene files around straight yarns, and a hand-built stitch mesh."""

import dataclasses
import math

import numpy as np

from data_formats import asset_pack as ap
from data_formats.stitch_mesh import StitchMesh, make_stitch_mesh
from data_formats.yarn_curves import make_yarn_curves, write_yarn_curves
from knitrun.shading import fiber_bcsdf as fb

DEG = math.pi / 180

# --- the bake -----------------------------------------------------------------------------------------------------

# per-stage settings that override a quality preset: every stage at its smallest useful size (a bake in seconds)
TINY = {
    "dual_scattering": {"n_theta": 8},
    "correction": {"n_v": 4, "n_theta": 2, "n_phi": 2, "rows": 8, "spp": 1, "batches": 2, "ds": {"n_theta": 8}},
    "shadowing": {"n_v": 4, "n_theta": 2, "n_phi": 2, "rows": 8, "spp": 1, "batches": 2},
    "textures": {"width": 32, "height": 8, "samples": 1, "ao_rays": 2},
    "flyaway": {"width": 32, "height": 8, "samples": 1},
    "environment": {"shape": (3, 3, 4, 3)},
    "interreflection": {"n_views": 2, "rows": 4, "spp": 1, "batches": 2},
    "closure": {"iterations": 3},
    "colour_closure": {"iterations": 1},
}

# --- asset packs --------------------------------------------------------------------------------------------------

YARN = {"name": "cotton1", "units": "cm", "radius": 0.04, "period": 0.15, "plies": 3}
BCSDF = {"r_color": [0.989, 0.959, 0.874], "tt_color": [0.999, 0.999, 0.999], "d_color": [0.1, 0.1, 0.1],
         "beta_r": math.radians(1.0), "beta_tt": math.radians(27.197), "gamma_tt": math.radians(38.269),
         "alpha_r": math.radians(-3.0), "alpha_tt": math.radians(1.5)}


def provenance():
    """A complete /provenance group."""
    return {"yarn_spec_toml": 'name = "cotton1"\n[geometry]\nplies = 3\n',
            "bake_settings": {"quality": "draft", "batches": 4, "directions": [8, 8]},
            "seed": 7, "code_version": "0.1.0", "created": "2026-01-31T12:00:00+00:00",
            "timings": {"dual_scattering": 1.5, "correction": 30.25},
            "sample_counts": {"correction/xi_M": {"batches": 4, "paths_per_batch": 1000}, "textures": 16}}


SIZES = {"N_theta": 7, "N_v": 5, "N_phi": 8, "H": 8, "W": 16, "N_a": 3, "N_b": 4, "N_c": 2, "N_d": 5, "N_k": 6,
         "N_kl": 3}
FLY_HW = {"H": 4, "W": 8}


def _shape(spec, level):
    """The shape of a schema table at mip ``level`` for the sizes ``SIZES``/``FLY_HW``."""
    out = []
    for p in spec.shape:
        if isinstance(p, int):
            out.append(p)
        else:
            base = (FLY_HW if spec.family == "flyaway" else SIZES)[p]
            out.append(max(1, base >> (level or 0)))
    return tuple(out)


def _random_table(rng, spec, shape):
    """Random finite values inside the spec's allowed ranges."""
    a = rng.uniform(0.05, 0.9, size=shape)
    if spec.value_range == (None, None) and spec.channel_ranges is None:
        a = a - 0.5  # signed (shifts)
    if spec.vector:
        v = rng.normal(size=shape[:-1] + (spec.vector,))
        v[..., 0] = np.abs(v[..., 0])
        v /= np.linalg.norm(v, axis=-1, keepdims=True)
        a[..., : spec.vector] = v * rng.uniform(0, 1, size=shape[:-1] + (1,))
    return a


def full_tables(seed=0, levels=3):
    """(tables, errors, table_attrs) of a pack with every table of the schema: random values in range, ``levels`` mip
    levels, per-entry errors for the Monte Carlo tables, and a self-described I_M parameterisation."""
    rng = np.random.default_rng(seed)
    tables, errors, attrs = {}, {}, {}
    for spec in ap.TABLES:
        names = [(spec.name.replace("{k}", str(k)), k) for k in range(levels)] if spec.mip else [(spec.name, None)]
        for name, level in names:
            shape = _shape(spec, level)
            tables[name] = _random_table(rng, spec, shape)
            # per-entry errors for the Monte Carlo tables, a scalar for the rest
            if spec.family in ("correction", "dual_scattering") and shape:
                errors[name] = rng.uniform(0, 0.01, size=shape)
            else:
                errors[name] = 0.002
    for k in range(levels):
        attrs[f"textures/flyaway/mip{k}"] = {"half_width": 0.09, "error_kind": "exact (deterministic ray casting)"}
    attrs["environment/I_M_TT_D"] = {"axes": [
        {"name": "cos_theta_j", "range": [0, 1], "definition": "cos θ_j"},
        {"name": "sin_theta_o", "range": [-1, 1], "definition": "sin θ_o", "units": "1"},
        {"name": "phi_j_minus_phi_o", "range": [-math.pi, math.pi], "wrap": "repeat", "units": "rad",
         "definition": "φ_j − φ_o"},
        {"name": "log10_lambda", "range": [-0.5, 4.0], "definition": "log10 λ_j"}]}
    return tables, errors, attrs


def write_full(path, **kw):
    """Write a pack with every table (``full_tables``); returns what was written."""
    tables, errors, attrs = full_tables(**kw)
    ap.write_pack(path, YARN, provenance(), BCSDF, tables, errors, attrs)
    return tables, errors, attrs

# --- the I_M table ------------------------------------------------------------------------------------------------

# rough enough for a small table to reach 2% (see test_lookup_matches_direct_quadrature); shifted lobes (α ≠ 0)
ROUGH = fb.params_from_values([0.25, 0.2, 0.15], [0.45, 0.4, 0.35], [0.25, 0.3, 0.35], 25 * DEG, 35 * DEG,
                              80 * DEG, -5 * DEG, 2.5 * DEG)
TEST_SHAPE = (16, 40, 12, 64)

# --- scenes -------------------------------------------------------------------------------------------------------

def write_scene(folder, curves, *, camera, lights, render="", name="s"):
    """A scene over ``curves`` (list of (n, 3) point arrays, PL) with cotton1 yarn; returns its path."""
    pts = [np.asarray(c, float) for c in curves]
    offsets = np.concatenate([[0], np.cumsum([len(c) for c in pts])]).astype(np.int64)
    points = np.concatenate(pts) if pts else np.zeros((0, 3))
    write_yarn_curves(folder / f"{name}.h5", make_yarn_curves(points[None], offsets, yarn_types=["cotton1"],
                                                             units="cm"))
    text = f"""format = "knit-scene"
version = "1.0"
units = "cm"
background = [0.1, 0.2, 0.3]
[[yarns]]
curves = "{name}.h5"
yarn = "cotton1"
{camera}
{lights}
[render]
msaa = 4
shadow_map_size = 256
srbf_count = 4
{render}
"""
    path = folder / f"{name}.toml"
    path.write_text(text)
    return path


FRONT = """[camera]
position = [0.0, 0.0, 1.0]
look_at = [0.0, 0.0, 0.0]
fov_deg = 30.0
width = 64
height = 48"""
SUN = """[[lights]]
type = "directional"
direction = [0.3, 0.6, 1.0]
irradiance = [2.0, 2.0, 2.0]"""
BACKLIT = """[[lights]]
type = "directional"
direction = [0.0, 0.3, -1.0]
irradiance = [2.0, 2.0, 2.0]"""  # from behind a yarn the FRONT camera sees, and a little above it
SKY = """[[lights]]
type = "environment"
builtin = "sky\""""
SIDE = """[camera]
position = [0.0, -1.0, 0.12]
look_at = [0.0, 0.0, 0.12]
up = [0.0, 0.0, 1.0]
fov_deg = 30.0
width = 48
height = 48"""  # from the side, at the middle of three yarns stacked 0.12 cm apart (z = 0, 0.12, 0.24)
OVERHEAD_SUN = """[[lights]]
type = "directional"
direction = [0.0, 0.0, 1.0]
irradiance = [2.0, 2.0, 2.0]"""  # straight down a stack: the bottom yarn lies behind two


def straight(n=9, length=0.6, z=0.0):
    """A straight yarn of ``n`` points along x, ``length`` long, at depth z (cm)."""
    return np.stack([np.linspace(-length / 2, length / 2, n), np.zeros(n), np.full(n, z)], axis=1)

# --- stitch meshes ------------------------------------------------------------------------------------------------

KNIT, PURL, YO, K2TOG, SSK = range(5)


def sample():
    """Three courses on unit cells, every stitch type, one wider course (hand-built; chart "\\kk / p/ok / kkkk").

    Boundary lines y = 0, 1, 2, 3 hold vertices 0-4, 5-9, 10-14, 15-18 at x = 0, 1, ...
    course 0: faces 0-3 knit; course 1: 4 purl, 5 k2tog over faces 1 and 2, 6 yarn-over at vertex 8, 7 knit;
    course 2: 8 ssk over faces 4 and 5, 9 knit over the yarn-over, 10 knit."""
    xy = [(x, 0) for x in range(5)] + [(x, 1) for x in range(5)] + [(x, 2) for x in range(5)] \
        + [(x, 3) for x in range(4)]
    vertices = np.array([(x, y, 0.0) for x, y in xy], float)
    faces = [(0, 1, 6, 5), (1, 2, 7, 6), (2, 3, 8, 7), (3, 4, 9, 8),
             (5, 6, 11, 10), (6, 7, 8, 12, 11), (8, 13, 12), (8, 9, 14, 13),
             (10, 11, 12, 16, 15), (12, 13, 17, 16), (13, 14, 18, 17)]
    types = [KNIT] * 4 + [PURL, K2TOG, YO, KNIT] + [SSK, KNIT, KNIT]
    offsets = np.concatenate([[0], np.cumsum([len(f) for f in faces])])
    return make_stitch_mesh(vertices, offsets, [v for f in faces for v in f], types, yarn_type="cotton1")


def assert_same(a, b):
    """Two stitch meshes are equal field by field (arrays: dtype, shape and values)."""
    for field in dataclasses.fields(StitchMesh):
        x, y = getattr(a, field.name), getattr(b, field.name)
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and x.shape == y.shape, field.name
            np.testing.assert_array_equal(x, y, err_msg=field.name)
        else:
            assert x == y, field.name
