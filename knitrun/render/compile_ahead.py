"""Compile-ahead for a cold first frame: a helper process compiles the later passes' kernels while the frame compiles
the rasterizer's.

On an empty kernel cache the strip renderer's first frame spends nearly all its time compiling Numba kernels, on one
core, one kernel after another (``benchmarks/profile_compile.py``: 37 s for the example patch, ~15 s of it the
``raster`` pass's kernels and ~14 s the ``shade`` pass's). Which kernels a frame calls, and their argument types,
depend on the scene (its layers and flyaways), not on the frame, so a second process can compile the
``shade`` and ``resolve`` kernels and the flyaway coverage (``pipeline.Renderer.compile_shading``: the passes run on
a frame with no shading point) into the shared on-disk cache while this one loads the packs, fits the environment
and rasterizes. Numba looks in its cache before it compiles, so when this process reaches those
kernels it loads them; ``Renderer.render`` waits for the helper before the ``shade`` pass rather than compile the
same kernels twice. The result is the same machine code either way: the images do not change.

The helper runs only when asked (``Renderer(..., compile_ahead=True)``; ``knitrun render`` asks) and only when the
cache lacks ``shade_regular``: on a warm cache it would only take a core from the frame. It is a fresh interpreter
(``python -m knitrun.render.compile_ahead``, the renderer's arguments pickled on its stdin; not ``multiprocessing``,
whose ``spawn`` re-runs the caller's main script) with this process's environment, so the same cache folder. If it
fails, the frame compiles what it needs itself (slower, never wrong) and says so in ``RenderResult.facts``. Numba
writes each cache file atomically, so the two processes may write the same entry. A caller that exits first leaves
the helper to finish (its entries serve the next run). The helper reads the scene's curves like any renderer (a
stitch-mesh entry is simulated at rest there too), which it does not need; a scene of many stitch meshes gains less.
"""

from __future__ import annotations

import dataclasses
import pickle
import subprocess
import sys
from pathlib import Path


def kernels_cached() -> bool:
    """Whether the on-disk kernel cache has an entry for ``strip_shading.shade_regular`` (it has one signature for
    every scene, ``strip_shading``, "One signature"): then the scene's kernels are most likely there already. Reads
    Numba's cache index path, a private attribute: a Numba that moved it reads as cached (no helper), the safe side."""
    from knitrun.render.strip_shading import shade_regular

    try:
        index = shade_regular._cache._cache_file._index_path
    except AttributeError:
        return True
    return Path(index).exists()


def helper_scene(scene):
    """The scene the helper compiles for: ``scene`` with one SRBF lobe. The lobes' count does not change the kernels'
    argument types, and one lobe fits in a fraction of a second where 16 take ~5 s (the helper starts before the
    caller's fit has filled the fit cache)."""
    return dataclasses.replace(scene, render=dataclasses.replace(scene.render, srbf_count=1))


def start_compile_ahead(scene, packs, features, samples_per_segment: int):
    """Start the helper for ``scene`` (arguments as ``pipeline.Renderer``'s) and return its ``subprocess.Popen``, or
    None when the cache has the kernels already. ``scene`` must pickle (``Scene`` does)."""
    if kernels_cached():
        return None
    scene = helper_scene(scene)
    process = subprocess.Popen([sys.executable, "-m", "knitrun.render.compile_ahead"], stdin=subprocess.PIPE,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    with process.stdin:
        process.stdin.write(pickle.dumps((scene, dict(packs or {}), features, samples_per_segment)))
    return process


def compile_shading(scene, packs, features, samples_per_segment):
    """The helper's work: a renderer of ``helper_scene`` (packs read, one lobe fitted or read from the fit cache)
    whose later passes run on no shading point."""
    from knitrun.render.pipeline import Renderer

    Renderer(scene, packs, features, samples_per_segment).compile_shading()


if __name__ == "__main__":
    compile_shading(*pickle.load(sys.stdin.buffer))
