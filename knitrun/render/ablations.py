"""The strip renderer's ablations (Huang et al. 2025 Fig. 7): which baked terms a render uses.

Plain Python, no kernels: the command line imports it for its ``--ablation`` choices without loading Numba.

``Features`` switch the baked terms off: without ``xi`` the correction is 1, without ``fiber_shadowing``
Ψ^Fiber_G = 1 (and no fiber lies between a visible fiber and the light), without ``flyaways`` no flyaway layer;
without ``interreflection`` no yarn-level inter-reflection (``knitrun.render.interreflection``); ``full_tables``
False shades with the rank-1 factors ξ_M ξ_N and Ψ_{G,M} Ψ_{G,N} (the paper's) instead of the pack's unfactorized
tables. ``ABLATIONS`` names the combinations, in the order of the paper's figure
(``ABLATION_ORDER``) with a label each (``ABLATION_LABELS``).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Features:
    """Which baked terms the renderer uses (all on: the full model)."""

    xi: bool = True
    fiber_shadowing: bool = True
    flyaways: bool = True
    interreflection: bool = True
    full_tables: bool = True  # the unfactorized ξ, Ψ^Fiber when the pack has them; False: the paper's factors


ABLATIONS = {
    "plain_ds": Features(xi=False, fiber_shadowing=False, flyaways=False),
    "xi": Features(xi=True, fiber_shadowing=False, flyaways=False),
    "xi_shadowing": Features(xi=True, fiber_shadowing=True, flyaways=False),
    "full": Features(),
    "no_tables": Features(xi=False, fiber_shadowing=False),  # the full renderer without ξ and Ψ^Fiber
    "factored": Features(full_tables=False),
    "no_interreflection": Features(interreflection=False),
}
ABLATION_ORDER = tuple(ABLATIONS)
ABLATION_LABELS = {"plain_ds": "plain DS", "xi": "+ ξ correction", "xi_shadowing": "+ fiber-level shadowing",
                   "full": "+ flyaways (full)", "no_tables": "full without ξ, Ψ^Fiber",
                   "factored": "full, rank-1 factored ξ, Ψ", "no_interreflection": "full without inter-reflection"}
