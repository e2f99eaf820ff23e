"""The strip renderer's ablations (Huang et al. 2025 Fig. 7): which baked terms a render uses.

Plain Python, no kernels: the command line imports it for its ``--ablation`` choices without loading Numba.

``Features`` switch the baked terms off: without ``xi`` the correction is 1, without ``fiber_shadowing``
Ψ^Fiber_G = 1 (and no fiber lies between a visible fiber and the light), without ``flyaways`` no flyaway layer;
without ``interreflection`` no yarn-level light transport: no inter-reflection (``knitrun.render.interreflection``)
and the geometric fiber count for light crossing a yarn instead of the one from the pack's transmittance T_Y
(``yarn_look``, ``dual_scattering.transmittance_count``); ``full_tables``
False shades with the rank-1 factors ξ_M ξ_N and Ψ_{G,M} Ψ_{G,N} (the paper's) instead of the pack's unfactorized
tables.

The full model (the defaults) draws the flyaway layer and shades the regular fibers with ξ closed on this renderer at
every view, apart on single and multiple scattering, looks the lights up on the tube surface the camera sees, reads the
textures with the axial parallax, tilts the fibers by the curve's bend and stretch and adds the light the neighbouring
yarns scatter onto each yarn. The flyaway layer lowers the yarn-scale error on six of the seven example scenes (its
hairs in their own yarn's shadow, and the regular fibers not already too bright: with the paper's ξ the lone yarn's
regular fibers alone are 15–16 % brighter than the reference traced without hairs under the sky and back-lit;
BENCHMARKS.md, "Issue 13: hairs in their own yarn's shadow, and the closed ξ with flyaways as the default", "Issue 13: ξ
closed on the strip renderer"). Measured at knit's stop 73 (``closed`` → ``full``, over the instance floor): the
straight yarn under the sky 1.09 → 0.98×, back-lit 1.67 → 1.16×, the patches 1.27 → 1.20×, 1.65 → 1.34×, 1.25 → 1.18×,
1.63 → 1.59× (directional, sky, grazing, simulated); on the front-lit straight yarn it raises the error, 0.81 → 0.87×
(both under the floor; the ensemble's 0.88 → 1.00×), where two fiber draws' hairs differ by 1.66× in single scattering
(BENCHMARKS.md, "Issue 13: the GL backend draws the default model, the bounce on the GPU, the texture tilt, the flyaway
layer (stop 73)").

The ξ closed at every view, the surface lookups, the parallax and the bounce became the default together in stop 49
(BENCHMARKS.md, "Issue 13: the default model of stop 49"): against the model without them
(``diagonal_xi+no_parallax+no_bounce+axis_shadows``) the yarn-scale error over the instance floor falls on the four
patches (1.70 / 1.58 / 1.80 / 2.02× → 1.51 / 1.46 / 1.70 / 1.87×: directional, grazing, sky, simulated) and the straight
yarn under the sky (1.14 → 1.04×), the back-lit and directional straight yarns move by +0.01 and +0.02×, and six of the
seven mean radiance ratios lie in [0.95, 1.05] instead of five (the back-lit yarn's is 1.058). Each alone does not: the
view-closed ξ darkens the patches unless the bounce gives back the light that the diagonal ξ's excess had stood in for,
and the surface lookups light legs that make the grazing patch too bright unless the ξ is right at grazing light.

``fiber_detail`` multiplies the regular fibers' radiance by the fiber-level detail of the pack's AO texture
(``yarn_look.fiber_detail``: each texel's ambient visibility over its row's mean), the crevices between plies
and fibers that Ψ^Fiber_G(v), a function of v alone, smooths away; it belongs with the fiber-level shadowing, so the
rungs without Ψ^Fiber go without it too. Measured in BENCHMARKS.md, "Issue 13: fiber-level detail".

``closed_xi`` shades with the pack's ``correction/xi_closed`` (ASSET_PACK.md §6, the bake's ``closure`` stage): ξ
made to close on this renderer where it was measured, instead of the paper's Ψ_*/Ψ_DS. A pack without it (schema
< 2.3, or baked with ``--only``) is shaded with the paper's ξ, and the render's facts say so (``facts["xi"]``). The
closed ξ exists only as a full table: the factored rung (``full_tables`` False) uses the paper's factors.
``view_xi`` shades with the pack's ``correction/xi_view`` (schema 2.4) instead: ξ(v, θ_i, θ_o, φ) closed at every
view and light, not only on the bake's diagonal θ_o = −θ_i; the ablation ``diagonal_xi`` reads the diagonal ξ. On
the straight yarn the view-closed ξ holds the brightness at every light angle where the diagonal ξ is up to 1.9×
too bright at grazing light; without the yarn-level bounce the patches are 1–5 % darker with it (BENCHMARKS.md,
"Issue 13: ξ closed at every view").

``multiple_scattering`` False keeps single scattering alone: the fiber BCSDF f of every directional light and the
environment's I_M, with Zinke's density factors d_f = d_b = 0 so that the DS terms of multiple scattering (local
back-scattering, forward-scattered light through other fibers, and the environment's multiple-scattering cells)
vanish, and without the yarn-level terms whose light another fiber scattered first: the bounce (``yarn_bounce``), the
body's glow on its hairs (``hair_glow``) and the sky's lobes inter-reflected between the yarns (``interreflection``'s
ρ_Y; its gap transmittance τ_Y, light that crossed a blocker unscattered, stays). Until stop 63 the glow and the
lobes' inter-reflection were counted as single scattering: 3–9 % of the example scenes' single scattering under a
directional light, 16 % of the patch's under the sky (BENCHMARKS.md, "Issue 13: single scattering, counted apart and
between the closure's cells"). It is no rung of the ladder but a split: the reference traced with one scattering event
(``trace_reference(..., max_depth=1)``) is its counterpart, and ``benchmarks/probe_split.py`` compares the two
halves of the light, single and multiple, scene by scene.

``parallax`` moves each regular point's texture coordinate and tangent along the yarn to the centre-line point whose
tube surface the camera sees there (``pipeline.parallax_shift``): nothing moves on a yarn across the view, a yarn
tilted toward the camera is read further along (both backends; the ablation ``no_parallax`` reads the strip point's
own). Alone it lowered the error on three patches of four but darkened the grazing-light patch (BENCHMARKS.md,
"Issue 13: single and multiple scattering, split"); in the default it darkens the grazing patch's lit legs back
(without it 1.174 of the reference's brightness, with it 1.041).

``fiber_bend`` tilts the regular fibers as the curve's bend and stretch tilt the reference's swept fibers
(``strip_shading.fiber_bend``: the texture tangent's component along the yarn scaled by λ (1 − κ·o); both backends, the
ablation ``no_bend`` shades every fiber as on a straight yarn at rest). The default since stop 69: on the four
patches the yarn-scale error over the instance floor falls 1.35 / 1.29 / 1.39 / 1.72× → 1.22 / 1.22 / 1.34 / 1.59×
(directional, grazing, sky, simulated; the straight yarns do not move), because the single scattering lies where
the reference's does (its own error over its floor on the simulated patch 2.03 → 1.83×) and its excess falls
(1.22 → 1.18× the reference's); the patches' means fall 0.5–2 %, uncovering the multiple scattering they lack
(BENCHMARKS.md, "Issue 13: the default test run on two workers, fibers tilted by a bend").

``yarn_bounce`` adds, under directional lights, the light the neighbouring yarns scatter onto a yarn
(``knitrun.render.yarn_bounce``: from the pack's hull albedo and transmittance, no fitted constant; it needs
``interreflection`` and ``multiple_scattering``; both backends, the ablation ``no_bounce`` leaves it out). A tube
spreads what its fibers scatter, not the light that crosses between them (``yarn_bounce.tube_optics``): until stop
49 it spread all of T_Y, τ_Y included, and the example patches came out 10–18 % too bright with it
(BENCHMARKS.md, "Issue 13: light that neighbouring yarns scatter", "Issue 13: the default model of stop 49").
Since stop 70 its tube phase is the pack's own straight yarn's (``correction/radiance_view`` over v) instead of a
Lambertian cylinder's, and ``hair_bounce`` lets the hairs of the flyaway layer take the neighbours' light too
(``strip_shading.hair_bounce``; both backends; the ablation ``no_hair_bounce`` leaves it to the bodies): the bounce was
0.45–0.56 of the light the example patches' yarns send each other in the reference (``benchmarks/probe_inter_yarn.py``,
the red examples), and is 0.82–0.87 with both; the directional patches' brightness goes from 0.938–1.002 of the
reference's to 0.992–1.033 (BENCHMARKS.md, "Issue 13: the neighbours' light by the yarn's own phase, and on the hairs
(stop 70)").

``split_xi`` shades with ξ closed apart on single and multiple scattering (the pack's ``correction/xi_view_ss`` and
``_ms``, or the diagonal's ``xi_closed_ss``, ``_ms``; schema 2.5, baked by every quality preset since stop 56, before
that with ``knitbake bake --split-xi``; ASSET_PACK.md §6 "Closure apart"): single scattering (the BCSDF f of the lit
fibers, and the environment's I_M) takes the first, the dual-scattering terms of multiple scattering the second. A
pack without them is shaded with the one closed ξ, and the render's facts say so. The default on both backends since
stop 56, with the standard pack's finer closure cells (17 × 17 × 9 instead of 8 × 8 × 8): one ξ closed on the sum of
the two made up for the renderer's multiple scattering, about half the path tracer's on the lone yarn, with single
scattering, and the red patches' dark channels came out 1.11–1.22× the reference's; apart they are 1.04–1.08×, and
the four patches' yarn-scale error over the instance floor falls from 1.47 / 1.63 / 1.42 / 1.87× to 1.41 / 1.54 /
1.36 / 1.76× (directional, sky, grazing, simulated; BENCHMARKS.md, "Issue 13: ξ closed apart as the default (stop
56)"). The ablation ``whole_xi`` shades with the one ξ.

``colour_xi`` (with ``split_xi`` at every view) reads ξ of multiple scattering in the yarn's colour, channel by
channel, from the pack's ``correction/xi_view_ms_by_colour`` (schema 2.7, baked by the ``colour_closure`` stage;
``yarn_look.ms_xi_in_colour``): closed on the white yarn alone it left the dark channels of a coloured yarn with
0.3–0.6 of the path tracer's multiple scattering (ASSET_PACK.md §6 "Against the colour"; BENCHMARKS.md, stop 77).
The default on both backends since stop 77 (the GL backend takes each entry's table from the CPU renderer's looks);
the ablation ``white_ms_xi`` reads the white yarn's in every colour.

``two_blockers`` counts up to two yarns between a point and a directional light instead of one: a depth-peeled
second shadow layer (``shadow_map``, ``behind``) gives V₂, the fraction of the light that at most one yarn blocks,
and the light passing between the fibers becomes V + (V₂ − V) τ_Y + (1 − V₂) τ_Y², the scattered rest crossing
(V₂ − V) + 2 (1 − V₂) yarns (``strip_shading.past_blockers``): under grazing light a point lies behind several
yarns, and one gap per blocked ray let too much through. The default on both backends since stop 71: on the grazing
patch, the one example scene with points behind two yarns, the mean ratio goes from 1.033 to 0.999 and the
yarn-scale error from 1.24× to 1.18× the instance floor (1.34× to 1.26× the ensemble floor), the other six scenes'
figures do not move, and the second layer is a peeled depth pass (+90–140 ms of a 0.9–1.1 s CPU frame there;
BENCHMARKS.md, "Two blocking yarns" (stop 47) and "Issue 13: two blocking yarns by default, on both backends (stop
71)"). The ablation ``one_blocker`` counts one.

``surface_shadows`` looks the lights up on the tube surface the camera sees at a regular point (the strip point moved
r √(1 − v²) toward the camera, ``pipeline.strip_receivers``) instead of on the strip plane through the yarn's axis, up
to a radius deeper: under the grazing patch's light the axis plane puts one leg of every stitch in its neighbours'
shadow, which the reference lights (the fully shadowed pixels hold 21.6 % of the reference's light there, 8.4 % with
the lookups on the surface; BENCHMARKS.md, "Issue 13: the error every stitch repeats, and shadows looked up on the
tube's surface"). Alone, with the diagonal ξ, it left the grazing patch 1.21× too bright (the lone yarn's brightness
at grazing light, which the axis plane's wrong shadows had hidden). Both backends draw it; the ablation
``axis_shadows`` looks up on the axis plane.

``hair_glow`` lights the hairs beside a yarn's body and in front of it (since stop 56), under directional lights, by the
light that body scatters (``strip_shading.body_glow``: the bounce's tube phase from the pack's hull albedo and
transmittance, the tube's solid angle from the hair). In front light the rows beside the straight yarn's body hold 42 %
light that the path-traced reference scatters more than once and the hairs' single scattering lacks (BENCHMARKS.md,
"Issue 13: the flyaway draw"). The default on both backends since stop 52 (measured on the seven scenes in
BENCHMARKS.md, stops 51–52); the ablation ``no_hair_glow`` leaves it out. The hairs over the body took no glow until
stop 56, though one reference draw's add twice the strips' light there (back-lit +24.4 against +11.1 %, in front light
+6.2 against +2.9 %); with it the back-lit yarn's brightness went from 0.909 to 0.929 of the reference's, the simulated
patch's from 0.936 to 0.958 and the grazing patch's from 1.031 to 1.055 (BENCHMARKS.md, stop 56).

``hairs_behind`` (since stop 57) takes a share of the hairs seen over a yarn's body to lie behind it, seen through its
gaps (``strip_shading.behind_share``: (1 − c)/(2 − c) where the body's coverage is c), lit past their own yarn
rather than by the body's Ψ^Fiber_G: the baked hair coverage holds them, and lit from behind they lie in the open
while Ψ^Fiber_G of the body's front is nearly 0. Both backends; the ablation ``no_hairs_behind`` takes every hair
over the body to lie in front of it, as until stop 56 (measured in BENCHMARKS.md, "Issue 13: hairs seen through the
body").

The hair canopy (since stop 60; the default on both backends since stop 61) dims each directional light by the hair
layers of the other yarns between a point and the light (``knitrun.render.hair_canopy``: shells of hair density from
the pack's flyaway coverage, other yarns' layers crossed by the beam, evaluated at the polyline points' tube surface
toward the light and interpolated along the curves). The shadow maps draw the yarns' bodies alone; traced on the
reference's fibers the other yarns' flyaways keep 8.5 % of the light off the lit regular fibers of the grazing patch's
interior and 2.9 % of the directional patch's (``benchmarks/probe_hair_canopy.py``), and the reference's regular
fibers seen between the hairs are that much darker than the strips' (``benchmarks/probe_first_surface.py``). With it
the grazing patch's brightness goes from 1.060 to 1.006 of the reference's and its yarn-scale error from 1.38 to 1.30×
the instance floor, the directional patch's from 0.997 to 0.980 and 1.38 to 1.37×, the simulated patch's from 0.957 to
0.944 (out of [0.95, 1.05]) at 1.74×; the lone yarns and the sky (no directional light) do not change; it costs no
measurable time (BENCHMARKS.md, stop 60). It became the default with the GL backend drawing it (the canopy at the
polyline points in a texture, as the bounce) and ``render.hair_layers`` 3 (stop 61): the ablation ``no_hair_canopy``
leaves it out.

``hair_light`` False draws the flyaway layer's hairs opaque and black: the image holds the light of the regular
fibers seen between the hairs. It is no rung of the ladder but a split, as ``multiple_scattering``: the reference
traced with ``seen="regular"`` (``knitbake.trace.reference.build_reference``: the light of the paths whose camera ray
first hits a regular fiber) is its counterpart, and the full image less it is the light the hairs send the camera,
what they scatter of the light and what they pass on of the yarn behind them (``benchmarks/probe_first_surface.py``).
CPU renderer only.

``ABLATIONS`` names the combinations as a ladder, each adding one term to the one before (``ABLATION_ORDER``):
plain DS, + ξ (the paper's), + Ψ^Fiber (with the fiber-level detail), + yarn-level inter-reflection and bounce, + ξ
closed on the renderer (at every view), + flyaways (= the full model, the default); every rung draws the surface
lookups and the parallax. Then the full model without the tables, with the paper's factored tables, without the
detail, with the paper's ξ, with ξ closed on the diagonal only, without the axial parallax, without the fiber
bend, without the yarn-level bounce, without it on the hairs, with the lookups on the axis plane, with one ξ closed
on single and multiple scattering together, with two blocking yarns counted, without the body's glow on its hairs,
with every hair seen over a body taken to lie in front of it and without other yarns' hair layers dimming the
directional lights.
``ABLATION_LABELS`` gives each a label; ``regular_fibers`` drops an ablation's flyaway layer.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace


@dataclass(frozen=True)
class Features:
    """Which baked terms the renderer uses (the defaults: the full model)."""

    xi: bool = True
    fiber_shadowing: bool = True
    flyaways: bool = True
    interreflection: bool = True  # yarn-level inter-reflection (ρ_Y) and transmission (T_Y)
    full_tables: bool = True  # the unfactorized ξ, Ψ^Fiber when the pack has them; False: the paper's factors
    fiber_detail: bool = True  # the fiber-level detail of the AO texture (yarn_look.fiber_detail)
    closed_xi: bool = True  # ξ closed on this renderer (correction/xi_closed) where the pack has it, else the paper's
    view_xi: bool = True  # with closed_xi: ξ closed at every view (correction/xi_view) where the pack has it
    multiple_scattering: bool = True  # False: single scattering alone (DS density factors d_f = d_b = 0)
    parallax: bool = True  # the regular points' texture coordinate and tangent where the tube's seen surface lies
    fiber_bend: bool = True  # the regular fibers tilted by the curve's bend and stretch (strip_shading)
    yarn_bounce: bool = True  # light the neighbouring yarns scatter onto a yarn under directional lights
    hair_bounce: bool = True  # with yarn_bounce: onto its hairs too (strip_shading.hair_bounce)
    split_xi: bool = True  # ξ closed apart on single and multiple scattering (correction/xi_*_ss, _ms) where the pack
    # has it, else the one closed ξ
    colour_xi: bool = True  # with split_xi: multiple scattering's ξ closed in the yarn's colour (xi_view_ms_by_colour)
    two_blockers: bool = True  # up to two yarns counted between a point and a directional light (second shadow layer)
    surface_shadows: bool = True  # regular points look their lights up on the tube surface seen, not the axis plane
    hair_glow: bool = True  # hairs beside and over a yarn lit by the light its body scatters (strip_shading.body_glow)
    hairs_behind: bool = True  # hairs seen through a body's gaps lie behind it (strip_shading.behind_share)
    hair_light: bool = True  # False: the hairs opaque and black, the regular fibers' light between them (a split)
    hair_canopy: bool = True  # other yarns' hair layers dim the directional lights (``knitrun.render.hair_canopy``)


_PAPERS = dict(closed_xi=False, flyaways=False)  # the rungs below the closure: the paper's ξ, no hairs
ABLATIONS = {
    "plain_ds": Features(xi=False, fiber_shadowing=False, interreflection=False, fiber_detail=False, **_PAPERS),
    "xi": Features(fiber_shadowing=False, interreflection=False, fiber_detail=False, **_PAPERS),
    "xi_shadowing": Features(interreflection=False, **_PAPERS),
    "interreflection": Features(**_PAPERS),
    "closed": Features(flyaways=False),
    "full": Features(),
    "no_tables": Features(xi=False, fiber_shadowing=False, fiber_detail=False),  # the full model without ξ and Ψ^Fiber
    "factored": Features(full_tables=False, closed_xi=False),
    "no_detail": Features(fiber_detail=False),
    "papers_xi": Features(closed_xi=False),
    "diagonal_xi": Features(view_xi=False),
    "no_parallax": Features(parallax=False),
    "no_bend": Features(fiber_bend=False),
    "no_bounce": Features(yarn_bounce=False),
    "no_hair_bounce": Features(hair_bounce=False),
    "axis_shadows": Features(surface_shadows=False),
    "whole_xi": Features(split_xi=False),
    "white_ms_xi": Features(colour_xi=False),
    "one_blocker": Features(two_blockers=False),
    "no_hair_glow": Features(hair_glow=False),
    "no_hairs_behind": Features(hairs_behind=False),
    "no_hair_canopy": Features(hair_canopy=False),
}
ABLATION_ORDER = tuple(ABLATIONS)
ABLATION_LABELS = {"plain_ds": "plain DS", "xi": "+ ξ correction", "xi_shadowing": "+ fiber-level shadowing",
                   "interreflection": "+ inter-reflection", "closed": "+ ξ closed on the renderer",
                   "full": "+ flyaways (full)", "no_tables": "full without ξ, Ψ^Fiber",
                   "factored": "full, the paper's rank-1 factored ξ, Ψ",
                   "no_detail": "full without the fiber-level detail", "papers_xi": "full with the paper's ξ",
                   "diagonal_xi": "full with ξ closed on the diagonal",
                   "no_parallax": "full without the axial parallax",
                   "no_bend": "full with every fiber tilted as on a straight yarn at rest",
                   "no_bounce": "full without the yarn-level bounce",
                   "no_hair_bounce": "full without the yarn-level bounce on the hairs",
                   "axis_shadows": "full with shadows looked up on the strip's axis plane",
                   "whole_xi": "full with one ξ closed on single and multiple scattering together",
                   "white_ms_xi": "full with multiple scattering's ξ closed on the white yarn alone",
                   "one_blocker": "full with one blocking yarn counted per ray",
                   "no_hair_glow": "full without the body's glow on its hairs",
                   "no_hairs_behind": "full with every hair seen over a body in front of it",
                   "no_hair_canopy": "full without other yarns' hair layers dimming the directional lights"}


def combined(name: str) -> Features:
    """The features of ablation ``name`` or of a combination "a+b+…" of ablations: the full model with every switch
    that one of them turns from the full model's turned (the switches are booleans, so two never disagree);
    ValueError naming the first unknown name."""
    full, changed = ABLATIONS["full"], {}
    for part in name.split("+"):
        if part not in ABLATIONS:
            raise ValueError(f"unknown ablation {part!r} ({', '.join(ABLATIONS)})")
        changed.update({f.name: getattr(ABLATIONS[part], f.name) for f in fields(Features)
                        if getattr(ABLATIONS[part], f.name) != getattr(full, f.name)})
    return replace(full, **changed)


def regular_fibers(name: str) -> Features:
    """Ablation ``name`` (or a combination "a+b", as ``combined``) without its flyaway layer: what a probe that traces
    its reference without flyaways compares (``benchmarks/probe_closure.py``, ``probe_orientation.py``)."""
    return replace(combined(name), flyaways=False)
