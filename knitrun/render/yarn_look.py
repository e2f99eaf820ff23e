"""What the strip renderer needs of one yarn entry, read from its asset pack (``data_formats/ASSET_PACK.md``).

``load_look(pack_path, entry, units, needs)`` opens only the datasets the scene uses (``needs``: corrections,
flyaways, environment) and converts everything to the scene:

* Lengths: the pack's `/yarn` lengths are in its own ``units``; they are converted to the scene's and scaled by
  ``entry.radius / pack radius`` (a scene may draw a yarn thicker or thinner than it was baked, ``SCENE.md``): the
  texture period and the flyaway strip half-width scale with it, so the fibers keep their proportions.
* Colour: the entry's ``color`` multiplies the BCSDF lobe colours A_R, A_TT, A_D (as the reference path tracer does).
  f is linear in those colours, so I_M and the dual-scattering averages ā_f, ā_b scale with the colour while the
  shifts and widths stay; Ā_b, Δ̄_b, σ̄_b are recomputed from them (``dual_scattering.backscatter_terms``), exactly. The
  correction ξ and the shadowing Ψ^Fiber are ratios and visibilities and are used as baked, but for ξ of multiple
  scattering where the pack has it closed in greys (``correction/xi_view_ms_by_colour``, schema 2.7): each channel
  reads it at its colour (``ms_xi_in_colour``), since the dual-scattering estimate and the path tracer's multiple
  scattering fall with the colour at different rates (ASSET_PACK.md §6 "Against the colour").
* Hull albedo ρ_Y (``/interreflection/albedo``, read with an environment light or with ``transmission``) and
  transmittance T_Y in the entry's colour (``hull_colour``): each channel read off the pack's curve against the
  colour (``/interreflection/*_by_colour``, schema 2.6: ρ_Y and T_Y of the yarn whose fibers' lobe albedos are
  scaled by k, linear in k between its samples) at that channel's colour; a pack without the curves (schema < 2.6)
  gives the white yarn's times the colour, a first-order approximation (cotton1 in the examples' red: T_Y 0.41 /
  0.11 / 0.08 against the curve's 0.37 / 0.21 / 0.20), and ``hull_from`` says which. ``hull_albedo`` (RGB) is the
  ρ_Y of the directional lights' yarn-level bounce (``yarn_bounce``) and, per channel, of the environment's
  inter-reflection, whose shadow pass takes its luminance (``yarn_albedo``; ``knitrun.render.interreflection``);
  None (neither term) for a pack baked before
  schema 2.1, which ``RenderResult.facts["interreflection"]`` then reports.
* Fiber counts for the dual-scattering estimate at run time: ``dual_scattering.fiber_counts`` (n_cross, n_occluded)
  from the yarn spec stored in the pack's provenance. With ``transmission`` and a pack that has the yarn's
  transmittance T_Y (``/interreflection/transmittance``, schema 2.2), n_cross, the count for light crossing another
  yarn, becomes ``dual_scattering.transmittance_count`` (the count that lets T_Y through; n_occluded stays, ξ was
  baked with it); ``YarnLook.n_cross_from`` says which.
* Gap transmittance τ_Y (``gap_transmittance``, with ``transmission``): the fraction of a beam crossing a yarn that
  passes between its fibers without meeting one, 1 − the mean of the pack's coverage texture (the bake's fraction of
  rays across the tube that hit a fiber). The renderer counts it as direct light past a blocking yarn under a
  directional light (``strip_shading``, SHADING.md §3), with ``n_cross_rest`` the count of the scattered rest,
  τ_Y + (1 − τ_Y) ā_f^{n_cross_rest} = T_Y; the environment's cells, whose inter-reflection holds T_Y whole, keep
  n_cross. 0 (and n_cross_rest = n_cross) without ``transmission`` or without T_Y in the pack.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from data_formats.asset_pack import read_pack
from data_formats.asset_pack.schema import CLOSURE_STAGE_VERSION
from data_formats.conventions import CM_PER_UNIT, LUMINANCE
from data_formats.errors import FormatError
from data_formats.yarn_spec import loads_spec
from knitrun.render.hair_canopy import hair_shells
from knitrun.render.interreflection import interreflected_visibility
from knitrun.render.shading_inputs import Corrections, Look
from knitrun.render.texture_sampling import MipStack, empty_mip_stack, mip_stack
from knitrun.render.yarn_bounce import phase_grid
from knitrun.shading.dual_scattering import (D_B, D_F, DS_NAMES, TABLE_NAMES, backscatter_terms, fiber_counts,
                                             pack_tables, transmittance_count)
from knitrun.shading.fiber_bcsdf import params_from_pack, tinted
from knitrun.shading.im_lookup import IMTable, im_table_from
from knitrun.shading.table_lookup import axis_cell, lookup_theta

CORRECTION_TABLES = ("correction/xi_M", "correction/xi_N", "shadowing/psi_GM", "shadowing/psi_GN")
FULL_TABLES = ("correction/xi", "shadowing/psi")  # optional: absent from packs baked without them
CLOSED_XI = "correction/xi_closed"  # optional (schema ≥ 2.3): the paper's ξ where a pack lacks it
VIEW_XI = "correction/xi_view"  # optional (schema ≥ 2.4): ξ closed at every (θ_i, θ_o), read when asked
# optional (schema ≥ 2.5): ξ closed apart on single (ss) and multiple (ms) scattering, on the diagonal and at every view
SPLIT_XI = {"ss": "correction/xi_closed_ss", "ms": "correction/xi_closed_ms"}
SPLIT_VIEW_XI = {"ss": "correction/xi_view_ss", "ms": "correction/xi_view_ms"}
MS_BY_COLOUR = "correction/xi_view_ms_by_colour"  # optional (schema ≥ 2.7): xi_view_ms closed on coloured yarns
ALBEDO_TABLE = "interreflection/albedo"  # optional: absent from packs of schema < 2.1
TRANSMITTANCE_TABLE = "interreflection/transmittance"  # optional: absent from packs of schema < 2.2
BY_COLOUR = {ALBEDO_TABLE: "interreflection/albedo_by_colour",  # optional: absent from packs of schema < 2.6
             TRANSMITTANCE_TABLE: "interreflection/transmittance_by_colour"}
TUBE_PHASE_TABLE = "correction/radiance_view"  # optional (schema ≥ 2.4): the yarn-level bounce's phase, ``tube_phase``


DETAIL_MAX = 4.0  # cap on the fiber-level detail D (a texel far brighter than its row: a lone lit fiber)

@dataclass
class YarnLook:
    """Runtime data of one yarn entry; lengths in scene units, tables float64 (textures float32)."""

    name: str
    params: np.ndarray  # (N_PARAMS,) fiber BCSDF with the entry's colour
    ds: np.ndarray  # (5, N_theta, 3) dual-scattering tables (pack_tables order)
    xi_full: np.ndarray  # (N_v, N_theta, N_phi, 3), or (0, 1, 1, 3) to use the factors
    xi_view: np.ndarray  # (N_v, N_theta_i, N_theta_o, N_phi, 3), or (0, 1, 1, 1, 3): ξ by xi_full / the factors
    xi_single: np.ndarray  # (N_v, N_theta, N_phi, 3) ξ of single scattering, or (0, 1, 1, 3): xi_full's for both
    xi_single_view: np.ndarray  # (N_v, N_theta_i, N_theta_o, N_phi, 3), or (0, 1, 1, 1, 3)
    xi_m: np.ndarray  # (N_v, N_theta, 3) or a (1, 1, 3) table of ones when corrections are not used
    xi_n: np.ndarray
    psi_full: np.ndarray
    psi_gm: np.ndarray
    psi_gn: np.ndarray
    tangent: MipStack
    coverage: MipStack
    detail: MipStack  # fiber-level detail, directional and environment (``fiber_detail``), or ones when not drawn
    flyaway: MipStack | None
    radius: float  # drawn yarn radius = regular strip half-width
    period: float  # texture period along the rest arc length
    flyaway_half_width: float
    hair_shells: tuple | None  # (edges, σ) of the hair layer (``hair_canopy.hair_shells``), None without flyaways
    n_cross: float  # fibers a beam crossing another yarn meets (``transmittance_count`` or geometric)
    n_cross_rest: float  # the count of what a crossing beam does not pass between the fibers (τ_Y split out)
    gap: float  # τ_Y: fraction of a beam crossing a yarn that passes between its fibers (``gap_transmittance``)
    n_cross_from: str  # where n_cross came from, for RenderResult.facts
    xi_from: str  # which ξ the regular fibers are shaded with (closed, the paper's), for RenderResult.facts
    warnings: list  # what the pack could not give that the features asked for (one line each)
    n_occluded: float
    d_f: float  # DS density factors (``dual_scattering.D_F``, ``D_B``); 0 and 0: single scattering alone
    d_b: float
    twist_sign: float  # +1 when the plies turn counter-clockwise seen along +z (ply angle grows with s), else −1
    hull_albedo: np.ndarray | None  # (3,) ρ_Y in the colour (``yarn_bounce``); None: no ρ_Y in the pack, or not read
    hull_transmittance: np.ndarray | None  # (3,) T_Y in the colour (``yarn_bounce``); None: no T_Y, or not read
    hull_from: str  # how ρ_Y and T_Y were put in the colour (``hull_colour``), for RenderResult.facts
    tube_phase: np.ndarray | None  # the bounce's phase Φ in the colour on ``yarn_bounce.phase_grid``; None: no table
    yarn_albedo: float | None  # luminance of hull_albedo (``interreflection``); None: the pack has no ρ_Y
    im: IMTable | None  # the I_M^{TT,D} table for ``im_lookup.im_kernel``
    residuals: dict  # xi / psi factorization residuals, for reports


def no_detail() -> MipStack:
    """One texel of 1 in both channels (``fiber_detail``): the fiber-level detail switched off."""
    return mip_stack([[np.ones((1, 1, 2), np.float32)]])


def ones_factor():
    """A (1, 1, 3) factor table of ones: the term switched off."""
    return np.ones((1, 1, 3))


def no_full_table():
    """An empty full table: lookups use the factors."""
    return np.zeros((0, 1, 1, 3))


def no_view_table():
    """An empty view-closed ξ table: ξ comes from the (v, θ_d, φ) table or its factors."""
    return np.zeros((0, 1, 1, 1, 3))


def _tinted_ds(tables, colour):
    if np.all(colour == 1.0):
        return pack_tables(tables)
    t = {n: np.asarray(tables[f"dual_scattering/{n}"], np.float64) for n in DS_NAMES}
    a_f, a_b = t["a_f"] * colour, t["a_b"] * colour
    big_a_b, delta_b, sigma_b = backscatter_terms(a_f, a_b, t["alpha_f"], t["alpha_b"], t["beta_f"], t["beta_b"])
    return pack_tables({"dual_scattering/a_f": a_f, "dual_scattering/beta_f": t["beta_f"],
                        "dual_scattering/A_b": big_a_b, "dual_scattering/Delta_b": delta_b,
                        "dual_scattering/sigma_b": sigma_b})


def gap_transmittance(coverage_levels) -> float:
    """τ_Y = 1 − the mean coverage of the pack's coverage texture (any level: the mip chain keeps the mean; level 0
    is read), the fraction of the bake's rays across the yarn tube, over v ∈ [−1, 1] and one period, that met no
    fiber: what a beam crossing the yarn keeps unscattered, averaged over where it crosses. Clipped to [0, 1)."""
    mean = float(np.asarray(coverage_levels[0], np.float64).mean())
    return min(max(1.0 - mean, 0.0), 1.0 - 1e-9)


def fiber_detail(ao_levels, coverage_levels, albedo: float) -> MipStack:
    """The fiber-level detail texture: two channels per texel, the directional lights' detail
    (``fiber_detail_chain`` of the AO texture) and the environment's (of the AO inter-reflected with the yarn's hull
    albedo ``albedo``, ρ_Y's luminance; 0: none)."""
    direct, ambient = fiber_detail_chain(ao_levels, coverage_levels), \
        fiber_detail_chain(ao_levels, coverage_levels, albedo)
    return mip_stack([[np.stack([d, a], axis=-1) for d, a in zip(direct, ambient)]])


def fiber_detail_chain(ao_levels, coverage_levels, albedo: float = 0.0) -> list:
    """The fiber-level detail of each mip level: the texel's ambient visibility over the coverage-weighted mean of its
    row, D = ao / ā(v) (1 where nothing is covered, at most ``DETAIL_MAX``). Along u it averages to 1 over the covered
    texels of a row, so it adds the fibers' contrast (the crevices between plies and fibers the AO texture holds,
    ASSET_PACK.md §8) without moving a row's brightness, which Ψ^Fiber_G(v) carries. With ``albedo`` ρ > 0 the
    visibility is first inter-reflected, ao' = ao / (1 − ρ (1 − ao)) (``interreflection.interreflected_visibility``):
    in a bright yarn a crevice the sky barely sees still gets the light its fiber walls scatter into it, as the
    environment's terms need (under a directional light the shadowing is directional and keeps the plain AO)."""
    out = []
    for ao, cov in zip(ao_levels, coverage_levels):
        ao, cov = np.asarray(ao, np.float64), np.asarray(cov, np.float64)
        if albedo > 0.0:
            ao = interreflected_visibility(ao, albedo)
        weight = cov.sum(axis=1, keepdims=True)
        mean = np.where(weight > 0, (ao * cov).sum(axis=1, keepdims=True) / np.where(weight > 0, weight, 1.0), 1.0)
        detail = np.where((cov > 0) & (mean > 0), ao / np.where(mean > 0, mean, 1.0), 1.0)
        out.append(np.clip(detail, 0.0, DETAIL_MAX).astype(np.float32))
    return out


def load_look(pack_path, entry, units: str, *, corrections=True, full_tables=True, flyaways=True,
              environment=False, detail=True, transmission=True, closed_xi=True, view_xi=False,
              split_xi=False, colour_xi=False) -> YarnLook:
    """Read ``pack_path`` for scene yarn ``entry`` (``data_formats.scene.YarnEntry``) in scene ``units``. Raises
    ``data_formats.errors.FormatError`` for an unreadable pack and ValueError (one line) for a pack that cannot
    serve the entry (another yarn, a missing table, an I_M parameterisation this renderer does not implement).
    ``full_tables``: use the unfactorized ξ and Ψ^Fiber when the pack has them, else the factors; ``detail``: the
    fiber-level detail from the pack's AO texture (``fiber_detail``; the environment's channel inter-reflected with
    ρ_Y's luminance under ``transmission``); ``transmission``: yarn-level transport,
    n_cross and the gap transmittance from the pack's transmittance T_Y and the hull albedo ρ_Y for the directional
    lights' bounce, where it has them (module docstring); ``closed_xi``: ξ from the pack's
    ``correction/xi_closed`` (closed on the diagonal θ_o = −θ_i, schema ≥ 2.3; ASSET_PACK.md §6) instead of the
    paper's, where the pack has it and ``full_tables`` (the closed ξ is a full table); ``view_xi`` (with
    ``closed_xi``: a closure at more views, not without it): from its ``correction/xi_view`` (closed at every view,
    schema ≥ 2.4) before the diagonal's; ``split_xi``: those closed apart on
    single and multiple scattering (``correction/xi_{closed,view}_{ss,ms}``, schema ≥ 2.5) instead, where the pack has
    them (multiple scattering's in ``xi_full``/``xi_view``, single's in ``xi_single``/``xi_single_view``);
    ``colour_xi`` (with the split ξ at every view): multiple scattering's from the pack's
    ``correction/xi_view_ms_by_colour`` in the entry's colour (schema ≥ 2.7, ``ms_xi_in_colour``) where it has it;
    ``YarnLook.xi_from`` says which ξ was read."""
    header = read_pack(pack_path, tables=[])
    spec = loads_spec(header.provenance["yarn_spec_toml"])
    if spec.name != entry.spec.name:
        raise FormatError(f"{pack_path}: pack baked for yarn {spec.name!r}, the scene draws {entry.spec.name!r}")
    stored = header.info
    flyaways = flyaways and spec.has_flyaways  # a yarn without flyaways has no flyaway textures to draw
    warnings = []
    if flyaways and "textures/flyaway/mip0" not in stored:
        flyaways = False
        warnings.append(f"{pack_path}: no flyaway textures (baked with --only): {spec.name} is drawn without its "
                        f"flyaway layer")
    names = list(TABLE_NAMES) + ["textures/tangent", "textures/coverage"]
    if corrections:
        names += list(CORRECTION_TABLES) + ["correction/xi_residual", "shadowing/psi_residual"]
    view_xi = corrections and closed_xi and view_xi and full_tables and VIEW_XI in stored
    closed_xi = corrections and closed_xi and full_tables and CLOSED_XI in stored and not view_xi
    split = (SPLIT_VIEW_XI if view_xi else SPLIT_XI) if corrections and split_xi and (view_xi or closed_xi) else {}
    split = split if all(n in stored for n in split.values()) else {}
    # the closure stage version of the closed ξ read (0: closed before version 4, which did not record it)
    closed_by = (list(split.values()) or [VIEW_XI if view_xi else CLOSED_XI]) if view_xi or closed_xi else []
    version = min((int(stored[n].attrs.get("closure_version", 0)) for n in closed_by), default=CLOSURE_STAGE_VERSION)
    if version < CLOSURE_STAGE_VERSION:
        warnings.append(f"{pack_path}: its ξ was closed by closure stage version {version or '< 4'}, older than "
                        f"this knit's (version {CLOSURE_STAGE_VERSION}; ASSET_PACK.md §6 says what each changed): "
                        f"re-bake the pack (knitbake bake reuses the stages that did not change)")
    colour_xi = colour_xi and split == SPLIT_VIEW_XI and MS_BY_COLOUR in stored
    if split:
        names += list(split.values()) + ([MS_BY_COLOUR] if colour_xi else [])
    elif view_xi:
        names.append(VIEW_XI)
    elif closed_xi:
        names.append(CLOSED_XI)
    if flyaways:
        names.append("textures/flyaway")
    if detail:
        names.append("textures/ao")
    if environment:
        names.append("environment/I_M_TT_D")
    if (environment or transmission) and ALBEDO_TABLE in stored:
        names.append(ALBEDO_TABLE)
    if transmission and TRANSMITTANCE_TABLE in stored:
        names.append(TRANSMITTANCE_TABLE)
    if transmission and ALBEDO_TABLE in stored and TUBE_PHASE_TABLE in stored:
        names.append(TUBE_PHASE_TABLE)
    names += [BY_COLOUR[n] for n in (ALBEDO_TABLE, TRANSMITTANCE_TABLE) if n in names and BY_COLOUR[n] in stored]
    missing = [n for n in names if n not in stored and f"{n}/mip0" not in stored]
    if corrections and full_tables:
        names += [n for n in FULL_TABLES if n in stored]
    if missing:
        raise FormatError(f"{pack_path}: pack lacks {', '.join(missing)} "
                          f"(bake the yarn again without --only or --scene)")
    pack = read_pack(pack_path, tables=[k for k in stored if any(k == n or k.startswith(n + "/mip") for n in names)])
    colour = np.asarray(entry.color, np.float64)
    params = tinted(params_from_pack(pack.fiber_bcsdf), colour)
    to_scene = CM_PER_UNIT[pack.yarn["units"]] / CM_PER_UNIT[units]
    pack_radius = float(pack.yarn["radius"]) * to_scene
    scale = entry.radius / pack_radius
    geometry = spec.geometry
    n_cross, n_occluded = fiber_counts(geometry, spec.radius)
    n_cross_from = (f"geometry ({'switched off' if not transmission else 'no transmittance in the pack, schema < 2.2'}"
                    f"): {n_cross:.2f}")
    gap, n_cross_rest, transmittance = 0.0, n_cross, None
    if TRANSMITTANCE_TABLE in names:
        transmittance = np.asarray(pack.tables[TRANSMITTANCE_TABLE], np.float64)
        gap = gap_transmittance(pack.mip_chain("textures/coverage"))
        a_f0 = lookup_theta(pack.tables["dual_scattering/a_f"], 0.0)
        geometric = n_cross
        n_cross = transmittance_count(transmittance, a_f0, geometric)
        n_cross_rest = transmittance_count(transmittance, a_f0, geometric, gap)
        n_cross_from = (f"transmittance T_Y = {float(transmittance @ LUMINANCE):.3f}: {n_cross:.2f}; of it τ_Y = "
                        f"{gap:.3f} between the fibers, the rest {n_cross_rest:.2f} (geometric {geometric:.2f})")
    tables = {n: np.asarray(pack.tables[n], np.float64) for n in names
              if n in CORRECTION_TABLES + FULL_TABLES + (CLOSED_XI, VIEW_XI) + tuple(split.values())}
    if CLOSED_XI in tables:
        tables["correction/xi"] = tables[CLOSED_XI]
    single, single_view = no_full_table(), no_view_table()
    if split and view_xi:
        tables[VIEW_XI], single_view = tables[split["ms"]], tables[split["ss"]]
        if colour_xi:
            tables[VIEW_XI] = ms_xi_in_colour(pack.tables[MS_BY_COLOUR], pack.info[MS_BY_COLOUR].axes[0].range,
                                              tables[split["ms"]], colour)
    elif split:
        tables["correction/xi"], single = tables[split["ms"]], tables[split["ss"]]
    xi_from = ("none (switched off)" if not corrections else
               ("closed on the renderer at every view" if view_xi else "closed on the renderer" if closed_xi
                else "the paper's" + ("" if full_tables else " factors") +
                ("" if CLOSED_XI in stored or not full_tables else f" (the pack has no {CLOSED_XI})"))
               + (", apart on single and multiple scattering" if split else
                  " (the pack has no ξ closed apart on single and multiple scattering)"
                  if split_xi and (view_xi or closed_xi) else "")  # the paper's ξ has no split: nothing to say
               + (", multiple scattering's closed in the yarn's colour" if colour_xi else ""))
    fly = pack.mip_chain("textures/flyaway") if flyaways else []
    im = None
    if environment:
        im = im_table_from(pack.tables["environment/I_M_TT_D"] * colour, pack.info["environment/I_M_TT_D"].axes)
    hull_albedo = hull_colour(pack, ALBEDO_TABLE, colour) if ALBEDO_TABLE in names else None
    hull_transmittance = None if transmittance is None else hull_colour(pack, TRANSMITTANCE_TABLE, colour)
    hull_from = (("none (not read: neither an environment nor transmission)" if ALBEDO_TABLE in stored else
                  "none (the pack has no ρ_Y, schema < 2.1)") if hull_albedo is None else
                 "the pack's curves against the colour" if BY_COLOUR[ALBEDO_TABLE] in names else
                 "the white yarn's times the colour (the pack has no curves against the colour, schema < 2.6)")
    residuals = {n.split("/")[1]: float(pack.tables[n]) for n in ("correction/xi_residual", "shadowing/psi_residual")
                 if corrections}
    phase = None
    if TUBE_PHASE_TABLE in names and hull_albedo is not None:
        phase = tube_phase(pack.tables[TUBE_PHASE_TABLE], pack.tables[ALBEDO_TABLE], hull_albedo, gap)
    return YarnLook(
        name=spec.name, params=params, ds=_tinted_ds(pack.tables, colour),
        xi_full=tables.get("correction/xi", no_full_table()), xi_view=tables.get(VIEW_XI, no_view_table()),
        xi_single=single, xi_single_view=single_view,
        xi_m=tables.get("correction/xi_M", ones_factor()),
        xi_n=tables.get("correction/xi_N", ones_factor()), psi_full=tables.get("shadowing/psi", no_full_table()),
        psi_gm=tables.get("shadowing/psi_GM", ones_factor()), psi_gn=tables.get("shadowing/psi_GN", ones_factor()),
        tangent=mip_stack([pack.mip_chain("textures/tangent")]),
        coverage=mip_stack([pack.mip_chain("textures/coverage")]),
        detail=fiber_detail(pack.mip_chain("textures/ao"), pack.mip_chain("textures/coverage"),
                            float(hull_albedo @ LUMINANCE) if transmission and hull_albedo is not None else 0.0)
        if detail else no_detail(),
        flyaway=mip_stack([[level[k] for level in fly] for k in range(3)]) if fly else None,
        radius=entry.radius, period=float(pack.yarn["period"]) * to_scene * scale,
        flyaway_half_width=(_half_width(pack, "textures/flyaway") * to_scene * scale) if fly else entry.radius,
        hair_shells=hair_shells(np.asarray(fly[0])[..., 3].mean(axis=(0, 2)),
                                _half_width(pack, "textures/flyaway") / _half_width(pack, "textures/coverage"))
        if fly else None,
        n_cross=n_cross, n_cross_rest=n_cross_rest, gap=gap, n_cross_from=n_cross_from, n_occluded=n_occluded,
        d_f=D_F, d_b=D_B, xi_from=xi_from,
        warnings=warnings,
        twist_sign=-1.0 if geometry.ply_clockwise else 1.0,
        hull_albedo=hull_albedo, hull_transmittance=hull_transmittance, hull_from=hull_from, tube_phase=phase,
        yarn_albedo=None if hull_albedo is None else float(hull_albedo @ LUMINANCE), im=im,
        residuals=residuals)


def ms_xi_in_colour(by_colour, log2_range, white, colour) -> np.ndarray:
    """ξ of multiple scattering (N_v, N_θ, N_θ, N_φ, 3) for a yarn drawn in the RGB ``colour``: channel c read at
    k = colour[c] off the samples of ``by_colour`` (N_k, N_v, N_θ, N_θ, N_φ, 3; ``correction/xi_view_ms_by_colour``,
    at the cell centres of the ``log2_colour_scale`` range ``log2_range``) and ``white`` (``correction/xi_view_ms``)
    at k = 1; between the two samples k_0 < k ≤ k_1 that bracket it linear in 1/k (ASSET_PACK.md §6 "Against the
    colour": where a path of two events dominates, the path tracer's multiple scattering falls as k² and the
    dual-scattering estimate as k³, so the ξ that closes them grows as 1/k), clamped at the darkest sample and at 1 (a
    channel of 0 reads the darkest, whose multiple scattering its colour then takes to 0)."""
    n = len(by_colour)
    lo, hi = log2_range
    scales = [2.0 ** (lo + (i + 0.5) * (hi - lo) / n) for i in range(n)] + [1.0]
    samples = [np.asarray(t, np.float64) for t in by_colour] + [np.asarray(white, np.float64)]
    out = np.empty(samples[-1].shape)
    for c in range(3):
        k = min(max(float(colour[c]), scales[0]), 1.0)
        i = next(j for j in range(1, n + 1) if k <= scales[j])
        f = (1.0 / scales[i - 1] - 1.0 / k) / (1.0 / scales[i - 1] - 1.0 / scales[i])  # the weight on k_1 = scales[i]
        out[..., c] = (1.0 - f) * samples[i - 1][..., c] + f * samples[i][..., c]
    return out


def hull_colour(pack, name: str, colour) -> np.ndarray:
    """ρ_Y or T_Y (``name``: ``ALBEDO_TABLE``, ``TRANSMITTANCE_TABLE``) of a yarn drawn in the RGB ``colour``: channel
    c read off the pack's curve ``BY_COLOUR[name]`` at k = colour[c] (linear between the samples of its
    ``colour_scale`` axis, clamped at its ends), or the white yarn's times the colour where the pack has no curve
    (module docstring)."""
    colour = np.asarray(colour, np.float64)
    curve = BY_COLOUR[name]
    if curve not in pack.tables:
        return np.asarray(pack.tables[name], np.float64) * colour
    table = np.asarray(pack.tables[curve], np.float64)
    lo, hi = pack.info[curve].axes[0].range
    out = np.empty(3)
    for c in range(3):  # the grid rule of ASSET_PACK.md §4.3, clamped
        i0, i1, f = axis_cell(float(colour[c]), lo, hi, table.shape[0], False)
        out[c] = (1.0 - f) * table[i0, c] + f * table[i1, c]
    return out


def tube_phase(radiance_view, white_albedo, albedo, gap: float) -> np.ndarray:
    """The yarn-level bounce's tube phase Φ (``yarn_bounce`` module docstring) on the shared grid
    (``yarn_bounce.phase_grid``): the pack's ``correction/radiance_view`` (N_v, N_θi, N_θo, N_φ, 3) of the white
    yarn averaged over v, each channel scaled to the colour by what the tube scatters, (ρ_Y − τ_Y) in the colour
    (``albedo``, ``hull_colour``) over the white yarn's (``white_albedo``), τ_Y ``gap``. The scale keeps the white
    yarn's angular shape: a darker colour holds less multiple scattering, whose share of the shape it leaves as it
    is (an approximation, the hull's own curve against the colour gives the amount)."""
    white = np.asarray(white_albedo, np.float64) - gap
    scale = np.divide(np.clip(np.asarray(albedo, np.float64) - gap, 0.0, None), white, out=np.zeros(3),
                      where=white > 1e-9)
    return phase_grid(np.asarray(radiance_view, np.float64).mean(axis=0) * scale)


def shading_look(look: YarnLook) -> tuple:
    """What the shading kernels receive for ``look`` (``shading_inputs``): (``Look``, ``Corrections``, the flyaway
    ``MipStack``, a one-texel stand-in of its three variants for a yarn without a flyaway layer)."""
    return (Look(look.params, look.ds, float(look.period), float(look.radius), float(look.flyaway_half_width),
                 float(look.n_occluded), float(look.n_cross), float(look.n_cross_rest),
                 float(look.gap), float(look.d_f), float(look.d_b)),
            Corrections(look.xi_full, look.xi_m, look.xi_n, look.psi_full, look.psi_gm, look.psi_gn, look.xi_view,
                        look.xi_single, look.xi_single_view),
            look.flyaway if look.flyaway is not None else empty_mip_stack(4, 3))


def _half_width(pack, base):
    return float(pack.info[f"{base}/mip0"].attrs["half_width"])
