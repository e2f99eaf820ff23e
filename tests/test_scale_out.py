"""Bakes on Dask (``knitbake.scale_out``, issue 17) on an embedded cluster of 2 worker processes × 1 thread:

* the layout gives workers × Numba threads = cores;
* a distributed bake writes the pack a serial bake writes: every table, per-entry error, attribute and the
  provenance but its timings and creation time, bit for bit;
* a worker killed (SIGKILL, by the test) while it runs a stage loses nothing: Dask reruns the task elsewhere and
  the pack is still identical;
* one yarn's failure is reported and the others finish.

Every bake here runs at test-sized settings (``TINY``, ``SMALL``): a real preset's closure takes minutes on one
thread.
"""

import dataclasses
import os
import signal
import time

import numpy as np
import pytest

from data_formats.asset_pack import read_pack
from data_formats.yarn_spec import load_preset
from knitbake.bake import bake
from knitbake.scale_out import bake_library, dask_client, local_layout, submit_bake
from tests.helpers import TINY

# for the killed worker: test-sized stage settings whose correction stage runs long enough (a few tenths of a second
# on one thread, against 0.03 s at TINY) to be caught running, and whose closure (8 times TINY's bins) iterates once;
# the other bakes here run at TINY (7 s a yarn)
SMALL = {**TINY, "correction": {**TINY["correction"], "rows": 16, "n_theta": 4, "n_phi": 4, "spp": 2},
         "closure": {**TINY["closure"], "iterations": 1}}


def _small(name="silk1", fibers=12):
    spec = load_preset(name)
    return dataclasses.replace(spec, geometry=dataclasses.replace(spec.geometry, fibers_per_ply=fibers))


def _assert_same_pack(a_path, b_path):
    a, b = read_pack(a_path), read_pack(b_path)
    assert set(a.tables) == set(b.tables) and set(a.stderr) == set(b.stderr)
    for name in a.tables:
        assert np.array_equal(a.tables[name], b.tables[name]), name
    for name in a.stderr:
        assert np.array_equal(a.stderr[name], b.stderr[name]), name
    assert a.yarn == b.yarn and a.fiber_bcsdf == b.fiber_bcsdf
    assert a.info.keys() == b.info.keys()
    for name, info in a.info.items():
        assert repr(info) == repr(b.info[name]), name
    strip = lambda p: {k: v for k, v in p.items() if k not in ("timings", "created")}  # noqa: E731
    assert strip(a.provenance) == strip(b.provenance)


@pytest.fixture(scope="module")
def client():
    with dask_client(workers=2) as c:
        yield c


def _serial_pack(folder, overrides):
    """The pack of ``_small()`` baked here at ``overrides``, in ``folder``/serial."""
    (folder / "serial").mkdir()
    path = folder / "serial" / "silk1.h5"
    bake(_small(), path, use_cache=False, overrides=overrides)
    return path


def test_the_local_layout_fills_the_cores_once():
    assert local_layout(cores=2) == (1, 2)
    assert local_layout(workers=2, cores=2) == (2, 1)
    assert local_layout(cores=16) == (8, 2)
    assert local_layout(workers=3, cores=2) == (3, 1)  # more workers than cores: one thread each, never zero


def test_the_workers_run_one_task_with_their_share_of_numba_threads(client):
    threads = client.run(lambda: (int(os.environ["NUMBA_NUM_THREADS"]), __import__("numba").get_num_threads()))
    assert sorted(threads.values()) == [(1, 1), (1, 1)]
    assert set(client.nthreads().values()) == {1}


def test_a_distributed_bake_writes_the_serial_pack(client, tmp_path):
    serial_pack = _serial_pack(tmp_path, TINY)
    results = bake_library(client, [(_small(), str(tmp_path / "silk1.h5"))], use_cache=False,
                           overrides=TINY)
    assert set(results["silk1"]) >= {"dual_scattering", "correction", "textures"}
    _assert_same_pack(serial_pack, tmp_path / "silk1.h5")


def test_a_worker_killed_mid_stage_loses_nothing(client, tmp_path):
    serial_pack = _serial_pack(tmp_path, SMALL)
    pids = client.run(os.getpid)
    victim = None
    for _ in range(5):  # a correction stage that ends between two looks is submitted again
        pack, stages = submit_bake(client, _small(), tmp_path / "silk1.h5", use_cache=False,
                                   overrides=SMALL)
        deadline = time.monotonic() + 120
        while victim is None and not pack.done() and time.monotonic() < deadline:
            for address, keys in client.processing().items():
                if any("correction" in str(key) for key in keys):
                    victim = pids[address]
            time.sleep(0.01)
        if victim is not None:
            break
    assert victim is not None, "never saw a correction stage running"
    os.kill(victim, signal.SIGKILL)
    pack.result(timeout=300)
    _assert_same_pack(serial_pack, tmp_path / "silk1.h5")
    assert set(client.run(os.getpid).values()) != set(pids.values())  # the nanny started a new worker


def test_one_yarns_failure_does_not_stop_the_others(client, tmp_path):
    results = bake_library(client, [(_small(), str(tmp_path / "missing" / "silk1.h5")),
                                    (_small("cotton1", 8), str(tmp_path / "cotton1.h5"))], overrides=TINY)
    assert isinstance(results["silk1"], Exception) and "does not exist" in str(results["silk1"])
    assert isinstance(results["cotton1"], dict) and (tmp_path / "cotton1.h5").exists()


def test_the_bake_library_command(tmp_path):
    """`knitbake bake-library`: refuses a missing folder or no yarn before starting a cluster; bakes spec files and
    presets into DIR/NAME.h5 with a summary row per yarn, at the preset's settings but those of --settings."""
    import tomli_w
    from click.testing import CliRunner

    from cli.knitbake_cli import main as knitbake
    from data_formats.yarn_spec import dumps_spec
    from knitbake.bake import QUALITY

    runner = CliRunner()
    result = runner.invoke(knitbake, ["bake-library", "-o", str(tmp_path)])
    assert result.exit_code == 2 and "name at least one yarn, or --all" in result.output
    result = runner.invoke(knitbake, ["bake-library", "silk1", "-o", str(tmp_path / "missing")])
    assert result.exit_code == 1 and "output folder does not exist" in result.output
    spec_file = tmp_path / "small_silk.toml"
    spec_file.write_text(dumps_spec(_small()))
    settings = tmp_path / "small.toml"
    settings.write_text(tomli_w.dumps(TINY))
    result = runner.invoke(knitbake, ["bake-library", str(spec_file), "-o", str(tmp_path), "--workers", "2",
                                      "--no-cache", "--settings", str(settings)])
    assert result.exit_code == 0, result.output
    assert "1 of 1 pack(s)" in result.output and (tmp_path / "silk1.h5").exists()
    baked = read_pack(tmp_path / "silk1.h5").provenance["bake_settings"]["settings"]
    assert baked["correction"] == {**QUALITY["draft"]["correction"], **TINY["correction"]}


def test_bake_library_passes_whole_xi_on(tmp_path, monkeypatch):
    """`--whole-xi` asks every yarn's closure for the one ξ alone, as `knitbake bake --whole-xi` does."""
    import contextlib

    from click.testing import CliRunner

    import knitbake.scale_out as scale_out
    from cli.knitbake_cli import main as knitbake

    seen = []

    def fake_library(client, jobs, quality, seed, use_cache, on_task, overrides):
        seen.append(overrides)
        return {spec.name: RuntimeError("not baked") for spec, _ in jobs}

    monkeypatch.setattr(scale_out, "dask_client", lambda *a: contextlib.nullcontext())
    monkeypatch.setattr(scale_out, "bake_library", fake_library)
    for flags in ([], ["--whole-xi"]):
        CliRunner().invoke(knitbake, ["bake-library", "silk1", "-o", str(tmp_path), *flags])
    assert seen == [None, {"closure": {"split": False}}]


def _small_scene():
    from data_formats.scene import load_scene

    scene = load_scene("examples/scenes/straight_yarn_directional.toml")
    return dataclasses.replace(scene, camera=dataclasses.replace(scene.camera, width=48, height=12))


def test_a_distributed_reference_is_the_serial_one_in_the_same_batches(client):
    """Sample batches on two workers, summed in batch order: the serial reference with the same batches, bit for
    bit; one batch (the default) is the plain render."""
    from knitbake.scale_out import submit_reference
    from knitbake.trace.reference import sample_batches, trace_reference

    assert sample_batches(10, 4) == [(0, 4), (4, 4), (8, 2)] and sample_batches(10, None) == [(0, 10)]
    scene = _small_scene()
    serial, facts = trace_reference(scene, 6, seed=3, batch_spp=2)
    image, dist_facts = submit_reference(client, scene, 6, seed=3, batch_spp=2).result(timeout=300)
    assert np.array_equal(serial, image) and dist_facts["batches"] == 3 and dist_facts["rays"] == facts["rays"]
    whole, _ = trace_reference(scene, 6, seed=3)
    np.testing.assert_allclose(whole, serial, rtol=1e-12, atol=1e-15)  # the same samples, summed in another order


def _set_env(name, value):
    """Set (None: remove) an environment variable in the process that runs this (a worker, by ``client.run``)."""
    if value is None:
        os.environ.pop(name, None)
    else:
        os.environ[name] = value


def test_a_rerun_reference_reuses_the_batches_that_finished(client, tmp_path, monkeypatch):
    """Every batch's sum is cached (its key: scene, curve bytes, batch, seeds, sources), so a rerun of an
    interrupted reference traces only the missing batches; a damaged entry is a miss, traced again."""
    from knitbake.scale_out import submit_reference

    monkeypatch.setenv("KNIT_CACHE_DIR", str(tmp_path))  # read where the tasks run: pass it to the workers too
    before = set(client.run(os.getenv, "KNIT_CACHE_DIR").values())
    client.run(_set_env, "KNIT_CACHE_DIR", str(tmp_path))
    try:
        scene = _small_scene()
        first, facts = submit_reference(client, scene, 4, seed=5, batch_spp=2).result(timeout=300)
        entries = sorted((tmp_path / "reference").iterdir())
        assert facts["batches_from_cache"] == 0 and len(entries) == 2
        entries[1].write_bytes(entries[1].read_bytes()[:100])  # the second batch "interrupted": a truncated entry
        again, facts = submit_reference(client, scene, 4, seed=5, batch_spp=2).result(timeout=300)
        assert facts["batches_from_cache"] == 1 and np.array_equal(first, again)
        _, facts = submit_reference(client, scene, 4, seed=6, batch_spp=2).result(timeout=300)
        assert facts["batches_from_cache"] == 0  # another seed, other batches
    finally:
        client.run(_set_env, "KNIT_CACHE_DIR", before.pop())


def test_a_reference_animation_split_on_dask_writes_the_serial_frames(tmp_path):
    """`knitbake reference --frames 0:2 --batch-spp 1 --workers 2`: every frame's batches as tasks on an embedded
    cluster; the EXR of each frame equals the serial command's with the same batches. `--resume` after an
    interrupted run traces only the missing frames, and only with the same settings."""
    from click.testing import CliRunner

    from cli.knitbake_cli import main as knitbake
    from cli.knitrun_cli import main as knitrun
    from data_formats.images import read_image

    runner = CliRunner()
    assert runner.invoke(knitrun, ["pattern", "stockinette", "--rows", "2", "--cols", "2", "-o",
                                   str(tmp_path / "m.h5")]).exit_code == 0
    result = runner.invoke(knitrun, ["simulate", str(tmp_path / "m.h5"), "--deform", "stretch-x=1.3", "--frames",
                                     "3", "-o", str(tmp_path / "anim.h5")])
    assert result.exit_code == 0, result.output
    (tmp_path / "anim.toml").write_text(
        'format = "knit-scene"\nversion = "1.0"\nunits = "cm"\n[[yarns]]\ncurves = "anim.h5"\nyarn = "cotton1"\n'
        '[camera]\nposition = [0.3, 0.3, 2.0]\nlook_at = [0.3, 0.3, 0.0]\northo_height = 1.0\nwidth = 24\n'
        'height = 16\n[[lights]]\ntype = "directional"\ndirection = [0.0, 0.5, 1.0]\nirradiance = [2, 2, 2]\n')
    args = ["reference", str(tmp_path / "anim.toml"), "--frames", "0:2", "--spp", "2", "--batch-spp", "1"]
    serial = runner.invoke(knitbake, [*args, "-o", str(tmp_path / "serial_#.exr")])
    assert serial.exit_code == 0, serial.output
    dist = runner.invoke(knitbake, [*args, "-o", str(tmp_path / "dist_#.exr"), "--workers", "2"])
    assert dist.exit_code == 0, dist.output
    for f in (0, 1):
        a, b = read_image(tmp_path / f"serial_{f}.exr"), read_image(tmp_path / f"dist_{f}.exr")
        assert np.array_equal(a, b) and a.max() > 0, f
    assert not np.array_equal(read_image(tmp_path / "serial_0.exr"), read_image(tmp_path / "serial_1.exr"))
    bad = runner.invoke(knitbake, [*args, "-o", str(tmp_path / "no_pattern.exr")])
    assert bad.exit_code == 1 and "needs a run of '#'" in bad.output
    # an interrupted run: frame 1 never written; --resume traces only it, and the same image
    frame1 = read_image(tmp_path / "serial_1.exr")
    for suffix in (".exr", ".png", ".json"):
        (tmp_path / f"serial_1{suffix}").unlink()
    before = (tmp_path / "serial_0.exr").stat().st_mtime_ns
    resumed = runner.invoke(knitbake, [*args, "-o", str(tmp_path / "serial_#.exr"), "--resume"])
    assert resumed.exit_code == 0 and "frame(s) 0 already traced" in resumed.output, resumed.output
    assert (tmp_path / "serial_0.exr").stat().st_mtime_ns == before
    assert np.array_equal(read_image(tmp_path / "serial_1.exr"), frame1)
    other = runner.invoke(knitbake, [*args[:-1], "2", "-o", str(tmp_path / "serial_#.exr"), "--resume"])
    assert other.exit_code == 0 and "already traced" not in other.output  # other settings: nothing skipped


def test_compare_traces_its_references_on_dask_with_the_same_images(tmp_path, pack):
    """`knitrun compare --workers 2`: the reference and both floors as tasks at once; the images equal the serial
    command's, so the report's figures do too."""
    import json

    from click.testing import CliRunner

    from cli.knitrun_cli import main as knitrun
    from data_formats.images import read_image
    from tests.helpers import FRONT, SUN, straight, write_scene

    scene = write_scene(tmp_path, [straight()], camera=FRONT, lights=SUN)
    reports = {}
    for name, extra in (("serial", []), ("dask", ["--workers", "2"])):
        result = CliRunner().invoke(knitrun, ["compare", str(scene), "--spp", "1", "--pack", f"cotton1={pack}",
                                              "-o", str(tmp_path / name), "--json", *extra])
        assert result.exit_code == 0, result.output
        reports[name] = json.loads(result.stdout)
    for image in ("reference.exr", "floor_instance.exr", "floor_monte_carlo.exr"):
        assert np.array_equal(read_image(tmp_path / "serial" / image), read_image(tmp_path / "dask" / image)), image
    for name, row in reports["serial"]["ablations"].items():
        assert row["yarn"] == reports["dask"]["ablations"][name]["yarn"], name
