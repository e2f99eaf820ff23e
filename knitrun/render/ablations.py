"""The strip renderer's ablations (Huang et al. 2025 Fig. 7): which baked terms a render uses.

Plain Python, no kernels: the command line imports it for its ``--ablation`` choices without loading Numba.

``Features`` switch the baked terms off: without ``xi`` the correction is 1, without ``fiber_shadowing``
Ψ^Fiber_G = 1 (and no fiber lies between a visible fiber and the light), without ``flyaways`` no flyaway layer;
without ``interreflection`` no yarn-level light transport: no inter-reflection (``knitrun.render.interreflection``)
and the geometric fiber count for light crossing a yarn instead of the one from the pack's transmittance T_Y
(``yarn_look``, ``dual_scattering.transmittance_count``); ``full_tables``
False shades with the rank-1 factors ξ_M ξ_N and Ψ_{G,M} Ψ_{G,N} (the paper's) instead of the pack's unfactorized
tables.

The flyaway layer is off by default: measured against the reference (BENCHMARKS.md, "Issue 13: hairs that pass
the body's light on"), it lowers the yarn-scale error on five of the seven example scenes but raises it on the
straight yarn under the sky and back-lit, where the regular fibers alone are already 13–16 % brighter than the
reference traced without flyaways and the hairs' light comes on top. ``flyaways`` draws it anyway.

``fiber_detail`` multiplies the regular fibers' radiance by the fiber-level detail of the pack's AO texture
(``yarn_look.fiber_detail_chain``: each texel's ambient visibility over its row's mean), the crevices between plies
and fibers that Ψ^Fiber_G(v), a function of v alone, smooths away; it belongs with the fiber-level shadowing, so the
rungs without Ψ^Fiber go without it too. Measured in BENCHMARKS.md, "Issue 13: fiber-level detail".

``closed_xi`` shades with the pack's ``correction/xi_closed`` (ASSET_PACK.md §6, the bake's ``closure`` stage): ξ
made to close on this renderer where it was measured, instead of the paper's Ψ_*/Ψ_DS. It is not the default:
measured in BENCHMARKS.md ("Issue 13: ξ closed on the strip renderer"), it brings the lone yarns' regular fibers
within −2.5 % … +5.4 % of the flyaway-free references but does not lower the patches' error.

``ABLATIONS`` names the combinations as a ladder, each adding one term to the one before (``ABLATION_ORDER``):
plain DS, + ξ, + Ψ^Fiber (with the fiber-level detail), + yarn-level inter-reflection (= the full model, the
default), + flyaways; then the full model without the tables, with the factored tables, without the detail, and
with the closed ξ (without and with flyaways).
``ABLATION_LABELS`` gives each a label.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Features:
    """Which baked terms the renderer uses (the defaults: the full model)."""

    xi: bool = True
    fiber_shadowing: bool = True
    flyaways: bool = False  # off by default: see the module docstring
    interreflection: bool = True  # yarn-level inter-reflection (ρ_Y) and transmission (T_Y)
    full_tables: bool = True  # the unfactorized ξ, Ψ^Fiber when the pack has them; False: the paper's factors
    fiber_detail: bool = True  # the fiber-level detail of the AO texture (yarn_look.fiber_detail_chain)
    closed_xi: bool = False  # the pack's ξ closed on this renderer (correction/xi_closed) instead of the paper's


ABLATIONS = {
    "plain_ds": Features(xi=False, fiber_shadowing=False, interreflection=False, fiber_detail=False),
    "xi": Features(fiber_shadowing=False, interreflection=False, fiber_detail=False),
    "xi_shadowing": Features(interreflection=False),
    "full": Features(),
    "flyaways": Features(flyaways=True),
    "no_tables": Features(xi=False, fiber_shadowing=False, fiber_detail=False),  # the full model without ξ and Ψ^Fiber
    "factored": Features(full_tables=False),
    "no_detail": Features(fiber_detail=False),
    "closed": Features(closed_xi=True),
    "closed_flyaways": Features(closed_xi=True, flyaways=True),
}
ABLATION_ORDER = tuple(ABLATIONS)
ABLATION_LABELS = {"plain_ds": "plain DS", "xi": "+ ξ correction", "xi_shadowing": "+ fiber-level shadowing",
                   "full": "+ inter-reflection (full)", "flyaways": "full + flyaways",
                   "no_tables": "full without ξ, Ψ^Fiber", "factored": "full, rank-1 factored ξ, Ψ",
                   "no_detail": "full without the fiber-level detail", "closed": "full, ξ closed on the renderer",
                   "closed_flyaways": "full + flyaways, ξ closed"}
