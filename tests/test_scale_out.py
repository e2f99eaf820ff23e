"""Bakes on Dask (``knitbake.scale_out``, issue 17) on an embedded cluster of 2 worker processes × 1 thread:

* the layout gives workers × Numba threads = cores;
* a distributed bake writes the pack a serial bake writes: every table, per-entry error, attribute and the
  provenance but its timings and creation time, bit for bit;
* a worker killed (SIGKILL, by the test) while it runs a stage loses nothing: Dask reruns the task elsewhere and
  the pack is still identical;
* one yarn's failure is reported and the others finish.
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


@pytest.fixture(scope="module")
def serial_pack(tmp_path_factory):
    path = tmp_path_factory.mktemp("serial") / "silk1.h5"
    bake(_small(), path, use_cache=False)
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


def test_a_distributed_bake_writes_the_serial_pack(client, serial_pack, tmp_path):
    results = bake_library(client, [(_small(), str(tmp_path / "silk1.h5"))], use_cache=False)
    assert set(results["silk1"]) >= {"dual_scattering", "correction", "textures"}
    _assert_same_pack(serial_pack, tmp_path / "silk1.h5")


def test_a_worker_killed_mid_stage_loses_nothing(client, serial_pack, tmp_path):
    pids = client.run(os.getpid)
    pack, stages = submit_bake(client, _small(), tmp_path / "silk1.h5", use_cache=False)
    victim = None
    deadline = time.monotonic() + 120
    while victim is None and time.monotonic() < deadline:
        for address, keys in client.processing().items():
            if any("correction" in str(key) for key in keys):
                victim = pids[address]
        time.sleep(0.05)
    assert victim is not None, "the correction stage never started"
    os.kill(victim, signal.SIGKILL)
    pack.result(timeout=300)
    _assert_same_pack(serial_pack, tmp_path / "silk1.h5")
    assert set(client.run(os.getpid).values()) != set(pids.values())  # the nanny started a new worker


def test_one_yarns_failure_does_not_stop_the_others(client, tmp_path):
    results = bake_library(client, [(_small(), str(tmp_path / "missing" / "silk1.h5")),
                                    (_small("cotton1", 8), str(tmp_path / "cotton1.h5"))])
    assert isinstance(results["silk1"], Exception) and "does not exist" in str(results["silk1"])
    assert isinstance(results["cotton1"], dict) and (tmp_path / "cotton1.h5").exists()


def test_the_bake_library_command(tmp_path):
    """`knitbake bake-library`: refuses a missing folder or no yarn before starting a cluster; bakes spec files and
    presets into DIR/NAME.h5 with a summary row per yarn."""
    from click.testing import CliRunner

    from cli.knitbake_cli import main as knitbake
    from data_formats.yarn_spec import dumps_spec

    runner = CliRunner()
    result = runner.invoke(knitbake, ["bake-library", "-o", str(tmp_path)])
    assert result.exit_code == 2 and "name at least one yarn, or --all" in result.output
    result = runner.invoke(knitbake, ["bake-library", "silk1", "-o", str(tmp_path / "missing")])
    assert result.exit_code == 1 and "output folder does not exist" in result.output
    spec_file = tmp_path / "small_silk.toml"
    spec_file.write_text(dumps_spec(_small()))
    result = runner.invoke(knitbake, ["bake-library", str(spec_file), "-o", str(tmp_path), "--workers", "2",
                                      "--no-cache"])
    assert result.exit_code == 0, result.output
    assert "1 of 1 pack(s)" in result.output and (tmp_path / "silk1.h5").exists()
