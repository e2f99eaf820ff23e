"""Work that outgrows one machine on Dask distributed (issue 17): bakes of many yarn types (one task per stage of
each yarn, one per pack) and references split into sample batches and frames.

Where the work runs
-------------------
* ``dask_client()`` without an address starts an embedded ``LocalCluster`` of worker *processes* sized to the
  machine: W workers (default: one per 2 cores, at least 1), each running one task at a time
  (``threads_per_worker=1``) with ``NUMBA_NUM_THREADS`` = cores // W, so workers × Numba threads = cores. Dask does
  not set that variable, and Numba's default threading layer aborts when two threads of one process launch
  parallel kernels at once, so one task per process is also what keeps the kernels safe.
* ``scheduler`` (or the environment variable ``KNIT_DASK_SCHEDULER``) sends the work to an existing cluster
  instead; its workers must be started with ``--nthreads 1`` and ``NUMBA_NUM_THREADS`` set (README, "Running on a
  cluster"), and must see the same stage-cache folder (``KNIT_CACHE_DIR``) and output folder.

What runs where
---------------
``bake_library`` submits, for each yarn, ``knitbake.bake.run_stage`` per stage (the same function a serial bake
calls: the stage cache is shared, so a rerun or another machine reuses finished stages) and one
``write_baked_pack`` task that depends on them. Stage results travel to the pack task through Dask (all of a
standard cotton1 pack's tables are 21 MiB; a whole standard bake peaks at 0.39 GiB resident in one process).
A stage is deterministic for its seed whatever the thread count, so a distributed bake writes the same tables,
errors and attributes as a serial one (the provenance's timings differ). A worker that dies mid-task loses
nothing: Dask reruns its task on another worker (up to ``distributed.scheduler.allowed-failures`` times) and the
result is the same.

``submit_reference`` splits a reference frame into sample batches (``knitbake.trace.reference.sample_batches``):
each task builds the scene's fibers where it runs (the sweep and Embree build, seconds for the example patches)
and returns the sum of its samples, cached (``reference_batch``) so that a rerun reuses the batches that finished;
one task adds the sums in batch order. A sample's random numbers depend only on
(seed, its index, its pixel), so the image equals ``trace_reference`` with the same ``batch_spp`` bit for bit. Frames
of an animation are independent references (one ``submit_reference`` per frame).
"""

from __future__ import annotations

import contextlib
import os

from data_formats.yarn_spec import YarnSpec
from knitbake.bake import STAGE_INPUTS, bake_plan, run_stage, write_baked_pack
from knitbake.trace.path_tracer import MAX_DEPTH
from knitbake.trace.reference import reference_batch, sample_batches

SCHEDULER_ENV = "KNIT_DASK_SCHEDULER"


def local_layout(workers: int | None = None, cores: int | None = None) -> tuple[int, int]:
    """(worker processes, Numba threads per worker) for an embedded cluster on ``cores`` (default: this machine's):
    ``workers`` (default: one per 2 cores, at least 1) and cores // workers threads (at least 1)."""
    cores = cores or len(os.sched_getaffinity(0))
    workers = max(1, int(workers) if workers else cores // 2)
    return workers, max(1, cores // workers)


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None):
    """A ``distributed.Client``: on ``scheduler`` (or ``$KNIT_DASK_SCHEDULER``) when given, else on an embedded
    ``LocalCluster`` laid out by ``local_layout``; closed (and the cluster stopped) on exit."""
    from distributed import Client, LocalCluster

    address = scheduler or os.environ.get(SCHEDULER_ENV)
    if address:
        with Client(address) as client:
            yield client
        return
    n, threads = local_layout(workers)
    env = {"NUMBA_NUM_THREADS": str(threads), "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    with LocalCluster(n_workers=n, threads_per_worker=1, processes=True, env=env, dashboard_address=":0") as cluster:
        with Client(cluster) as client:
            yield client


def submit_bake(client, spec: YarnSpec, output, quality: str = "draft", seed: int = 0, use_cache: bool = True,
                overrides=None) -> tuple:
    """Submit the bake of ``spec`` into ``output``: (future of its summary, as ``knitbake.bake.bake`` returns it;
    the futures of its stage tasks). Checks the plan (seed, quality, memory) before anything is submitted."""
    settings, stages = bake_plan(spec, quality, seed=seed, overrides=overrides)
    tag = os.urandom(4).hex()
    stage_futures = {}
    for stage in stages:  # the closures (last) wait for their input stages' futures
        inputs = {s: stage_futures[s] for s in STAGE_INPUTS[stage]} if stage in STAGE_INPUTS else None
        stage_futures[stage] = client.submit(run_stage, spec, stage, settings[stage], seed, use_cache, None, inputs,
                                             pure=False, key=f"{spec.name}-{stage}-{tag}")
    pack = client.submit(write_baked_pack, spec, str(output), quality, settings, stages, None, seed, stage_futures,
                         pure=False, key=f"{spec.name}-pack-{tag}")
    return pack, list(stage_futures.values())


def bake_library(client, jobs: list[tuple[YarnSpec, str]], quality: str = "draft", seed: int = 0,
                 use_cache: bool = True, on_task=None, overrides=None) -> dict:
    """Bake every (spec, output) of ``jobs`` on ``client``; returns {yarn name: summary, or the exception that
    stopped it} (one yarn's failure does not stop the others). ``on_task(finished, total)`` is called as each task
    (stage or pack) ends; ``overrides`` as for ``knitbake.bake.bake``."""
    from distributed import as_completed

    packs, tasks = {}, []
    for spec, output in jobs:
        pack, stages = submit_bake(client, spec, output, quality, seed, use_cache, overrides)
        packs[pack] = spec.name
        tasks += [*stages, pack]
    out = {}
    for i, future in enumerate(as_completed(tasks), 1):
        if future in packs:
            try:
                out[packs[future]] = future.result()
            except Exception as exc:  # noqa: BLE001  (reported per yarn)
                out[packs[future]] = exc
        if on_task:
            on_task(i, len(tasks))
    return out


def submit_reference(client, scene, spp: int, seed: int = 0, fiber_seed: int | None = None, max_depth: int = MAX_DEPTH,
                     batch_spp: int | None = None, geometry: str = "curves", use_cache: bool = True):
    """Submit the reference of ``scene`` (at its ``render.frame``): one task per sample batch (each builds the
    fibers where it runs and renders its samples, ``reference_batch``, whose sums are cached so that a rerun of an
    interrupted reference reuses the batches that finished) and one that adds their sums in batch order and
    divides by spp. A future of (image, facts): the image ``trace_reference`` gives with the same ``batch_spp``,
    bit for bit."""
    fiber_seed = seed if fiber_seed is None else fiber_seed
    tag = os.urandom(4).hex()
    parts = [client.submit(reference_batch, scene, first, count, seed, fiber_seed, max_depth, geometry, use_cache,
                           pure=False, key=f"reference-f{scene.render.frame}-s{first}-{tag}")
             for first, count in sample_batches(spp, batch_spp)]
    facts = {"width": scene.camera.width, "height": scene.camera.height, "spp": spp, "batch_spp": batch_spp,
             "seed": seed, "fiber_seed": fiber_seed, "max_depth": max_depth, "frame": scene.render.frame}
    return client.submit(_sum_batches, parts, spp, facts, pure=False, key=f"reference-f{scene.render.frame}-{tag}")


def _sum_batches(parts, spp, facts):
    total = None
    for part, _ in parts:  # in batch order: the sum a serial reference makes
        total = part if total is None else total + part
    image = total / spp
    seconds, rays = sum(f["render_s"] for _, f in parts), sum(f["rays"] for _, f in parts)
    build = {k: v for k, v in parts[0][1].items() if k not in ("render_s", "rays", "cached")}
    return image, {**facts, "render_s": seconds, "rays": rays, "rays_per_s": rays / seconds if seconds else 0.0,
                   "batches": len(parts), "batches_from_cache": sum(f["cached"] for _, f in parts), **build,
                   "mean_rgb": image.reshape(-1, 3).mean(axis=0).tolist()}
