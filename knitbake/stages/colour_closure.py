"""Close ξ of multiple scattering on a coloured yarn: the ``colour_closure`` stage of the bake (ASSET_PACK.md §6,
"Against the colour").

The closure (``closure.py``) closes ξ_ms on the white yarn: the renderer's dual-scattering terms times ξ_ms give the
path tracer's multiple scattering of the bake's straight yarn. A scene colour c multiplies the fibers' lobe albedos
A_R, A_TT, A_D per channel (``fiber_bcsdf.tinted``), and the two sides do not follow it alike. A path of n
scattering events carries c^n, so the path tracer's multiple scattering is Σ_{n≥2} c^n L_n, dominated by two events
where c is small. Zinke's dual-scattering estimate (Zinke et al. 2008), which the renderer evaluates with the
coloured averages ā_f, ā_b, reaches a point behind n fibers through ā_f^n and back through A_b, whose first term
holds three events (ā_b ā_f²): at small c it falls as c³ and faster. With the white's ξ_ms the strips' multiple
scattering was 0.40 / 0.32 of the path tracer's in the green and blue channels of the examples' red
(0.9, 0.25, 0.2) on the lone straight yarn, 0.06 / 0.03 lit from behind, and 0.47–0.56 on the red patches
(BENCHMARKS.md, "Issue 13: the multiple scattering of a coloured yarn (stop 77)").

Method. For each colour scale k of the ``log2_colour_scale`` axis (k = 1/8, 1/4, 1/2; at k = 1 the closure's
``correction/xi_view_ms`` is the white yarn's), on the closure's yarn, camera and bins:

* the path tracer's multiple scattering Ψ_MS(k) = Ψ_*(k) − k Ψ_SS: Ψ_*(k) traced with the lobe albedos times k,
  Ψ_SS the closure's one-event radiance (``correction/radiance_view_ss``), which is linear in k (one event carries
  k once), both traced again here batch by batch on the closure's fibers and seeds (``closure.trace_view_samples``)
  and subtracted per batch: their first events are the same paths, so the difference has no single-scattering
  noise (from the stored means, whose errors add, no bin at k = 1/8 and 5 % of them at 1/4 were measured to
  25 % on cotton1 standard);
* the renderer's, S_MS(k) = S(k) − k S_SS: S(k) the strips drawn in the grey k with the closure's ξ_ss and this k's
  ξ_ms (``closure.render_bins``), S_SS the strips' single scattering drawn once in white with the closure's ξ_ss (the
  BCSDF f is linear in the colour: ``tests/test_closure.py`` checks it);
* ξ_ms(k) ← ξ_ms(k) · Ψ_MS(k) / S_MS(k), ``iterations`` times, by the closure's rules
  (``closure.part_ratio``: the bins measured to ``MAX_RELATIVE_ERROR`` alone, else their angle bin summed over v),
  within ``CLAMP`` of the white's ξ_ms (the closure keeps that within ``CLAMP`` of the paper's ξ). The greys are
  closed from the lightest: k = 1/2 starts from the white's ξ_ms, each darker grey from the lighter two's ratio
  carried on (``continuation``), which is what a bin keeps where this grey's light is too faint to measure (at
  k = 1/8, from the white's, 111 of 41 616 bins moved on cotton1 standard: stop 77). The rms log of closed over
  start on the bins a grey closed (attribute ``start_rms_log``, per k; 0 where none closed) is the relative error
  of the bins it kept.

The last render measures the residual |S_MS/Ψ_MS − 1| over the bins used (attributes ``closure_residual_max``,
``closure_residual_rms`` of the stored table, over every k). Stored: ``correction/xi_view_ms_by_colour``
(N_k, N_v, N_θ, N_θ, N_φ, 3). A renderer reads each channel of a colour c at k = c, with ``xi_view_ms`` as the
sample at k = 1 (``knitrun.render.yarn_look.ms_xi_in_colour``: linear in 1/k between the samples, clamped at 1/8
and 1).

Errors. As the closure's split ξ: the relative standard error of Ψ_MS(k) over the batches, or of its angle bin's
sums where the bin moved by them; elsewhere the start's, at least its measured miss (``start_rms_log``: that grey's,
else the last grey's that closed a bin, else 1).

Cost: per k, the closure's batches of traces and ``iterations`` + 1 renders of every bin; once, its batches of
one-event traces and one render in white.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from data_formats.asset_pack import AXES
from data_formats.asset_pack.schema import CLOSURE_STAGE_VERSION
from data_formats.conventions import cell_centres
from knitbake.stages.closure import (CLAMP, CLOSURE_INPUTS, MAX_RELATIVE_ERROR, SIGNAL, part_ratio,
                                     render_bins, trace_view_samples)
from knitbake.stages.stage_result import StageResult

COLOUR_CLOSURE_INPUTS = CLOSURE_INPUTS + ("closure",)
TABLE = "correction/xi_view_ms_by_colour"
N_COLOURS = 3  # cells of the log2_colour_scale axis: k = 1/8, 1/4, 1/2


def colour_scales(n_colours: int = N_COLOURS) -> np.ndarray:
    """The k of the ``log2_colour_scale`` axis' ``n_colours`` cell centres (ASSET_PACK.md §4.2), ascending."""
    return 2.0 ** cell_centres(*AXES["log2_colour_scale"].range, n_colours)


def close_by_colour(spec, inputs: dict, write_pack_to, rows: int, iterations: int, spp: int, batches: int,
                    seed: int, progress=None) -> tuple[np.ndarray, np.ndarray, dict, dict]:
    """(ξ_ms by colour (N_k, N_v, N_θ, N_θ, N_φ, 3), its error, counts, the table's attributes: the residual's max
    and rms and ``start_rms_log`` per k) (module docstring).
    ``inputs``: stage → StageResult of ``COLOUR_CLOSURE_INPUTS``; ``write_pack_to(path, xi_view, split)`` as the
    closure's; ``rows``, ``spp``, ``batches``: the closure's."""
    closure = inputs["closure"]
    tables, errors = closure.tables, closure.errors
    if "correction/xi_view_ms" not in tables:
        raise ValueError("colour closure: the closure stage was baked without the split ξ (closure setting split)")
    closed, xi_ss, xi_ms = (tables[f"correction/xi_view{s}"] for s in ("", "_ss", "_ms"))
    white_relative = errors["correction/xi_view_ms"] / np.maximum(xi_ms, 1e-300)
    shape = xi_ms.shape[:4]
    per_view = int(np.prod(shape[1:]))
    scales = [float(k) for k in colour_scales()]
    passes_per_colour = batches + iterations + 1
    total = (1 + batches + len(scales) * passes_per_colour) * per_view

    def at(first_pass):
        if progress is None:
            return None
        return lambda done, _: progress(first_pass * per_view + done, total)

    out, out_err = {}, {}
    counts = {"colours": len(scales), "iterations": iterations, "bins": int(np.prod(shape))}
    misses = []
    miss, start_miss = 1.0, np.zeros(len(scales))  # how far a start was from the closed ξ (rms log), see below
    with tempfile.TemporaryDirectory(prefix="knit-colour-closure-") as tmp:
        pack = Path(tmp) / "inputs.h5"
        write_pack_to(pack, closed, (xi_ss, xi_ms))
        drawn_single = render_bins(pack, spec, shape, rows, at(0), split=True, single=True)
        grid = (shape[0], shape[1], shape[3])
        single = trace_view_samples(spec, grid, rows, spp, batches, seed, 1, at(1))  # the closure's, batch by batch
        for j in reversed(range(len(scales))):  # the lightest grey first: each darker one starts from them
            k = scales[j]
            first = 1 + batches + (len(scales) - 1 - j) * passes_per_colour
            whole = trace_view_samples(spec, grid, rows, spp, batches, seed, progress=at(first), colour_scale=k)
            apart = whole - k * single  # per batch: the first event's noise cancels (trace_view_samples)
            want, want_err = apart.mean(axis=0), apart.std(axis=0, ddof=1) / np.sqrt(batches)
            whole = whole.mean(axis=0)
            measured = np.all((want > SIGNAL * whole.max()) & (want_err <= MAX_RELATIVE_ERROR * np.abs(want)),
                              axis=-1, keepdims=True)
            start, start_relative = continuation(k, out, out_err, xi_ms, white_relative)
            xi = start.copy()
            moved, pooled_any = np.zeros(xi.shape, bool), np.zeros(xi.shape, bool)
            for it in range(iterations + 1):
                write_pack_to(pack, closed, (xi_ss, xi))
                drawn = render_bins(pack, spec, shape, rows, at(first + batches + it), split=True, colour_scale=k)
                drawn_ms = drawn - k * drawn_single
                used = measured & (drawn_ms > SIGNAL * drawn.max())
                if it == iterations:
                    break
                ratio, pooled = part_ratio(want, want_err, drawn_ms, used, SIGNAL * whole.sum(axis=0).max(),
                                           SIGNAL * drawn.sum(axis=0).max())
                xi = np.clip(xi * ratio, xi_ms / CLAMP, xi_ms * CLAMP)
                moved |= used
                pooled_any |= pooled & ~moved
            pooled_any &= ~moved
            pooled_relative = (np.sqrt((want_err ** 2).sum(axis=0, keepdims=True))
                               / np.maximum(np.abs(want.sum(axis=0, keepdims=True)), 1e-300))
            checked = moved & (xi > 0.0) & (start > 0.0)
            if checked.any():  # how far the start was from what this grey closed: the error of the bins it kept
                miss = start_miss[j] = float(np.sqrt(np.mean(np.log(xi[checked] / start[checked]) ** 2)))
            relative = np.where(moved, want_err / np.where(moved, np.abs(want), 1.0),
                                np.where(pooled_any, pooled_relative, np.maximum(start_relative, miss)))
            out[k], out_err[k] = xi, xi * relative
            counts[f"bins_closed_k{k:g}"] = int(moved.all(axis=-1).sum())
            counts[f"bins_pooled_k{k:g}"] = int(pooled_any.all(axis=-1).sum())
            counts[f"clamped_k{k:g}"] = int(np.isclose(xi, xi_ms * CLAMP).any(axis=-1).sum())
            misses.append(np.abs(drawn_ms[used] / want[used] - 1.0))
    off = np.concatenate(misses) if misses else np.zeros(0)
    residual = {"closure_residual_max": float(off.max()) if off.size else 0.0,
                "closure_residual_rms": float(np.sqrt(np.mean(off ** 2))) if off.size else 0.0,
                "start_rms_log": [round(float(x), 6) for x in start_miss]}
    return np.stack([out[k] for k in scales]), np.stack([out_err[k] for k in scales]), counts, residual


def continuation(k, closed, closed_err, white, white_relative):
    """(ξ_ms at grey k before it is closed, the relative error its inputs carry into it). ``closed``,
    ``closed_err``: grey → ξ_ms and its error of the greys closed so far (all lighter than k); ``white``,
    ``white_relative``: the closure's ξ_ms at k = 1 and its relative error. With one sample lighter than k (the
    white), the white's; with two or more, the nearest two's ratio carried on in log k, ξ(k₁) (ξ(k₁)/ξ(k₂))^p,
    p = log(k/k₁)/log(k₁/k₂) (at the halving greys ξ(2k)²/ξ(4k)), within ``CLAMP`` of the white's. ξ_ms grows as
    the grey darkens (the path tracer's two-event light falls as k², the dual-scattering estimate as k³; on cotton1
    standard the median over the white's was 2.1 at k = 1/2 and 3.5 at 1/4), and the carried ratio predicted the
    closed k = 1/4 at a median 1.03 and an rms log error of 0.34 (from the white's 1.31; ξ(1/2) alone 0.67;
    BENCHMARKS.md, stop 78). ``close_by_colour`` adds how far the start was from the bins it closed."""
    samples = sorted([(1.0, white, white * white_relative)] + [(g, closed[g], closed_err[g]) for g in closed],
                     key=lambda sample: sample[0])
    lighter = [sample for sample in samples if sample[0] > k]
    if len(lighter) < 2:
        return white.copy(), white_relative
    (k1, xi1, err1), (k2, xi2, err2) = lighter[0], lighter[1]
    power = np.log(k / k1) / np.log(k1 / k2)
    ok = (xi1 > 0.0) & (xi2 > 0.0)
    ratio = np.where(ok, xi1 / np.where(ok, xi2, 1.0), 1.0)
    xi = np.clip(xi1 * ratio ** power, white / CLAMP, white * CLAMP)
    return xi, np.sqrt(((1.0 + power) * err1 / np.maximum(xi1, 1e-300)) ** 2
                       + (power * err2 / np.maximum(xi2, 1e-300)) ** 2)


def bake_colour_closure_stage(spec, settings, seed, progress=None, inputs=None, write_pack_to=None) -> StageResult:
    """Stage ``colour_closure`` of ``knitbake.bake``: settings ``rows``, ``spp``, ``batches`` (the closure's),
    ``iterations`` and ``inputs`` (the settings of ``COLOUR_CLOSURE_INPUTS``, part of the cache key only).
    ``inputs``: their StageResults; ``write_pack_to``: see ``closure.close_correction``."""
    table, error, counts, residual = close_by_colour(spec, inputs, write_pack_to, settings["rows"],
                                                     settings["iterations"], settings["spp"], settings["batches"],
                                                     seed, progress)
    kind = (f"standard error of the path-traced multiple scattering Ψ_MS(k) over {settings['batches']} independent "
            "batches, carried into the ξ closed on it (where a bin kept its start, the start's inputs' and at least "
            "the start's measured miss, attribute start_rms_log)")
    attrs = {TABLE: {"error_kind": kind, "closure_version": CLOSURE_STAGE_VERSION, **residual}}
    return StageResult({TABLE: table}, {TABLE: error}, attrs, counts)
