"""Hostile inputs, damaged caches and concurrent runs (issue 19): each test reproduces one defect of the probe and
checks that it is gone.

* A damaged stage-cache entry of each kind (a flipped byte, truncated, empty, valid but edited) is detected, reported
  in the stage's ``cache_warning``, baked again into the same tables, and rewritten (issue 19, item 1).
* Files we write get the mode a plain ``open(..., "w")`` would: 0666 less the umask, or the mode of the file they
  replace (item 2).
* Two bakes of one yarn sharing a cache, at once in two processes, both succeed with identical packs (item 3).
* A temporary file left by a killed writer is removed by the next write to its path; a live writer's is kept
  (item 12).
* An output that is also an input, two outputs on one file, or an output in a missing folder is refused in one line
  before any work (items 10 and 11).
* Legal but extreme yarn and scene values are refused in one line naming the fields before anything is allocated
  (the memory budget), and the ranges that ran for minutes are closed (item 4).
* A pack that declares a huge table, HDF5 files that point outside themselves, FIFOs, folders and devices given as
  files are refused without reading or blocking (items 5, 6, 13).
* Arguments past int64 (an OBJ face index, a seed) are named, not tracebacks (item 8); our own errors are one line,
  any other exception is reported as a bug (item 9).
* The smaller defects: an unknown ``--pack`` name, ``--only ''``, coordinates of 1e300, a symlinked output, and the
  time report of a long simulation (item 13).
"""

import dataclasses
import os
import re
import stat
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from data_formats.asset_pack import read_pack
from data_formats.atomic import atomic_path
from data_formats.images import write_exr, write_png
from data_formats.yarn_curves import make_yarn_curves, write_yarn_curves
from data_formats.yarn_spec import load_preset
from knitbake.bake import bake, cache_dir
from tests.helpers import TINY

ONLY = ["dual_scattering", "shadowing"]


def _small_yarn():
    spec = load_preset("silk1")
    return dataclasses.replace(spec, geometry=dataclasses.replace(spec.geometry, fibers_per_ply=12))


def _flip_byte(path):
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    path.write_bytes(bytes(data))


def _truncate(path):
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


def _empty(path):
    path.write_bytes(b"")


def _edit_a_table(path):
    """A valid entry whose first table was changed in range, its stored checksum kept (tampering)."""
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    name = next(k for k in arrays if k.startswith("t:"))
    arrays[name] = arrays[name] * 1.01
    with open(path, "wb") as f:
        np.savez(f, **arrays)


@pytest.mark.parametrize("damage", [_flip_byte, _truncate, _empty, _edit_a_table])
def test_a_damaged_cache_entry_is_detected_rebaked_and_rewritten(tmp_path, monkeypatch, damage):
    monkeypatch.setenv("KNIT_CACHE_DIR", str(tmp_path / "cache"))
    clean = bake(_small_yarn(), tmp_path / "a.h5", overrides=TINY, only=ONLY)
    assert not any(r["cached"] for r in clean.values())
    entry = next(cache_dir().glob("shadowing-*.npz"))
    damage(entry)
    again = bake(_small_yarn(), tmp_path / "b.h5", overrides=TINY, only=ONLY)
    assert again["dual_scattering"]["cached"] and not again["shadowing"]["cached"]
    assert "baking again" in again["shadowing"]["cache_warning"]
    a, b = read_pack(tmp_path / "a.h5"), read_pack(tmp_path / "b.h5")
    assert all(np.array_equal(a.tables[n], b.tables[n]) for n in a.tables)
    third = bake(_small_yarn(), tmp_path / "c.h5", overrides=TINY, only=ONLY)  # the entry was rewritten
    assert all(r["cached"] and "cache_warning" not in r for r in third.values())


def _writes(folder):
    """One file of each writer kind: a pack, yarn curves, a PNG and an EXR."""
    image = np.full((4, 4, 3), 0.5, np.float32)
    write_png(folder / "i.png", image)
    write_exr(folder / "i.exr", image)
    write_yarn_curves(folder / "c.h5", make_yarn_curves(np.zeros((1, 2, 3)) + [[[0, 0, 0], [1, 0, 0]]],
                                                        np.array([0, 2]), yarn_types=["cotton1"]))
    return [folder / n for n in ("i.png", "i.exr", "c.h5")]


@pytest.mark.parametrize("umask", [0o022, 0o077, 0o002])
def test_written_files_follow_the_umask(tmp_path, umask):
    old = os.umask(umask)
    try:
        paths = _writes(tmp_path)
        with atomic_path(tmp_path / "t.json") as tmp:
            tmp.write_text("{}")
        paths.append(tmp_path / "t.json")
    finally:
        os.umask(old)
    for path in paths:
        assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~umask, path.name


def test_replacing_a_file_keeps_its_mode(tmp_path):
    target = tmp_path / "i.png"
    target.write_bytes(b"old")
    os.chmod(target, 0o640)
    old = os.umask(0o077)
    try:
        write_png(target, np.zeros((2, 2, 3), np.float32))
    finally:
        os.umask(old)
    assert stat.S_IMODE(target.stat().st_mode) == 0o640 and target.read_bytes()[:4] == b"\x89PNG"


def test_a_killed_writers_temporary_is_removed_and_a_live_ones_kept(tmp_path):
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    dead_pid = int(dead.stdout)
    stale = tmp_path / f".out.txt.{dead_pid}.abc123.tmp"
    live = tmp_path / f".out.txt.{os.getppid()}.def456.tmp"
    other = tmp_path / f".other.txt.{dead_pid}.abc123.tmp"
    for path in (stale, live, other):
        path.write_text("partial")
    with atomic_path(tmp_path / "out.txt") as tmp:
        tmp.write_text("done")
    assert not stale.exists() and live.exists() and other.exists()
    assert (tmp_path / "out.txt").read_text() == "done"


def test_two_bakes_of_one_yarn_at_once_both_succeed_with_identical_packs(tmp_path):
    """Two processes bake the same yarn with one shared, empty cache, started together: both write the same cache
    entries at about the same time."""
    code = textwrap.dedent(f"""
        import dataclasses, sys
        from data_formats.yarn_spec import load_preset
        from knitbake.bake import bake
        from tests.helpers import TINY
        spec = load_preset("silk1")
        spec = dataclasses.replace(spec, geometry=dataclasses.replace(spec.geometry, fibers_per_ply=12))
        bake(spec, sys.argv[1], overrides=TINY, only={ONLY!r})
    """)
    env = dict(os.environ, KNIT_CACHE_DIR=str(tmp_path / "cache"), NUMBA_NUM_THREADS="1")
    env.pop("NUMBA_CACHE_DIR", None)
    runs = [subprocess.Popen([sys.executable, "-c", code, str(tmp_path / f"{k}.h5")], env=env, cwd=os.getcwd(),
                             stderr=subprocess.PIPE, text=True) for k in "ab"]
    for run in runs:
        _, err = run.communicate(timeout=600)
        assert run.returncode == 0, err[-2000:]
    a, b = read_pack(tmp_path / "a.h5"), read_pack(tmp_path / "b.h5")
    assert set(a.tables) == set(b.tables) and all(np.array_equal(a.tables[n], b.tables[n]) for n in a.tables)
    assert not list((tmp_path / "cache" / "bake").glob("*.tmp"))


def test_two_writers_of_one_cache_entry_interleaved_both_succeed(tmp_path, monkeypatch):
    """The deterministic form of the race above: while one bake writes a cache entry, another writes and renames the
    same entry (here: from inside the first one's write). With one fixed temporary name per entry the first rename
    then found no file; with a temporary per writer both succeed and the entry is whole."""
    import knitbake.bake as kb
    from knitbake.stages.stage_result import StageResult

    result = StageResult({"x/y": np.arange(6.0).reshape(2, 3)}, {"x/y": 0.5}, {}, {"samples": 3})
    path = tmp_path / "stage-key.npz"
    real_savez, nested = np.savez, []

    def savez_while_another_writer_finishes(file, **arrays):
        real_savez(file, **arrays)
        if not nested:
            nested.append(True)
            kb._save_stage(path, result)

    monkeypatch.setattr(np, "savez", savez_while_another_writer_finishes)
    kb._save_stage(path, result)
    loaded, problem = kb._load_stage(path)
    assert nested and problem is None and np.array_equal(loaded.tables["x/y"], result.tables["x/y"])
    assert [p.name for p in tmp_path.iterdir()] == ["stage-key.npz"]


def test_an_output_that_is_an_input_or_in_a_missing_folder_is_refused_before_any_work(tmp_path):
    """Item 10: `simulate m.h5 -o m.h5` replaced the mesh, `fibers -o a.h5 --preview a.h5` left only the PNG; item 11:
    `reference -o nodir/r.exr` traced the whole image first, `fibers -o ok.bcc --preview nodir/x.png` kept ok.bcc."""
    from click.testing import CliRunner

    from cli.knitbake_cli import main as knitbake
    from cli.knitrun_cli import main as knitrun

    runner = CliRunner()
    mesh = tmp_path / "m.h5"
    made = runner.invoke(knitrun, ["pattern", "stockinette", "--rows", "2", "--cols", "2", "-o", str(mesh)])
    assert made.exit_code == 0
    before = mesh.read_bytes()
    cases = [(knitrun, ["simulate", str(mesh), "-o", str(mesh)], "both an input and an output"),
             (knitbake, ["fibers", "cotton1", "-o", str(tmp_path / "a.h5"), "--preview", str(tmp_path / "a.h5")],
              "two outputs"),
             (knitbake, ["reference", "examples/scenes/straight_yarn_directional.toml", "-o",
                         str(tmp_path / "nodir" / "r.exr"), "--spp", "64"], "does not exist"),
             (knitbake, ["fibers", "cotton1", "-o", str(tmp_path / "ok.bcc"), "--preview",
                         str(tmp_path / "nodir" / "x.png")], "does not exist"),
             (knitrun, ["convert", str(tmp_path / "c.h5"), str(tmp_path / "c.h5")], "both an input and an output")]
    write_yarn_curves(tmp_path / "c.h5", make_yarn_curves(np.zeros((1, 2, 3)) + [[[0, 0, 0], [1, 0, 0]]],
                                                          np.array([0, 2]), yarn_types=["cotton1"]))
    for program, args, message in cases:
        result = runner.invoke(program, args)
        assert result.exit_code == 1 and message in result.output and len(result.output.strip().splitlines()) == 1, \
            (args, result.output)
    assert mesh.read_bytes() == before
    assert not (tmp_path / "a.h5").exists() and not (tmp_path / "ok.bcc").exists()


def _within(seconds, call, unblock):
    """``call()`` run in a thread; if it is still running after ``seconds`` (blocked on a FIFO), ``unblock()`` frees
    it and the test fails: a read that blocks is the defect."""
    import threading

    out = {}
    thread = threading.Thread(target=lambda: out.setdefault("result", call()), daemon=True)
    thread.start()
    thread.join(seconds)
    if thread.is_alive():
        unblock()
        thread.join(10)
        pytest.fail(f"blocked for {seconds} s")
    return out["result"]


def _writer_of(fifo):
    def unblock():
        fd = os.open(fifo, os.O_WRONLY | os.O_NONBLOCK)
        os.close(fd)
    return unblock


@pytest.mark.parametrize("command", [["validate"], ["inspect"], ["render", "-o", "x.png"]])
def test_a_fifo_is_refused_without_blocking(tmp_path, command):
    """Item 6: a FIFO given as a pack, a scene or any input blocked `validate` and `render` forever."""
    from click.testing import CliRunner

    from cli.knitbake_cli import main as knitbake
    from cli.knitrun_cli import main as knitrun

    fifo = tmp_path / "scene.toml"
    os.mkfifo(fifo)
    program = knitrun if command[0] == "render" else knitbake
    args = [command[0], str(fifo), *[str(tmp_path / a) if a.endswith(".png") else a for a in command[1:]]]
    result = _within(30, lambda: CliRunner().invoke(program, args), _writer_of(fifo))
    assert result.exit_code == 1 and "is a FIFO, not a regular file" in result.output, result.output
    assert len(result.output.strip().splitlines()) == 1


def _curves_file(path):
    write_yarn_curves(path, make_yarn_curves(np.array([[[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]]), np.array([0, 3]),
                                             yarn_types=["cotton1"]))
    return path


def _external_storage(f):
    f.create_dataset("extra", shape=(16,), dtype="u1", external=[("/etc/passwd", 0, 16)])


def _external_fifo(f):
    fifo = os.path.join(os.path.dirname(f.filename), "pipe")
    os.mkfifo(fifo)
    del f["points"]
    f.create_dataset("points", shape=(3, 3), dtype="f4", external=[(fifo, 0, 36)])


def _external_link(f):
    f["extra"] = __import__("h5py").ExternalLink("/etc/other.h5", "/points")


def _virtual(f):
    import h5py

    layout = h5py.VirtualLayout(shape=(3, 3), dtype="f4")
    layout[:] = h5py.VirtualSource("/etc/other.h5", "points", shape=(3, 3))
    f.create_virtual_dataset("extra", layout)


@pytest.mark.parametrize("damage, message", [(_external_storage, "keeps its data in another file"),
                                             (_external_fifo, "keeps its data in another file"),
                                             (_external_link, "is an external link"),
                                             (_virtual, "is a virtual dataset")])
def test_hdf5_files_that_point_outside_themselves_are_refused(tmp_path, damage, message):
    """Item 6: a dataset with external storage was followed (it read /etc/passwd, or blocked on a FIFO)."""
    import h5py
    from click.testing import CliRunner

    from cli.knitbake_cli import main as knitbake

    path = _curves_file(tmp_path / "c.h5")
    with h5py.File(path, "a") as f:
        damage(f)
    fifo = tmp_path / "pipe"
    for command in ("validate", "inspect"):
        result = _within(30, lambda: CliRunner().invoke(knitbake, [command, str(path)]),
                         _writer_of(fifo) if fifo.exists() else (lambda: None))
        assert result.exit_code == 1 and message in result.output, result.output


@pytest.mark.parametrize("shape, message", [((1 << 16, 1 << 16), "more than the 8 GiB"),
                                            ((40000, 40000), "never written")])
def test_a_pack_that_declares_a_huge_table_is_refused_before_reading(tmp_path, shape, message):
    """Item 5: a ~1 MB pack declared a 5 GiB chunked table that was never written; `validate` read it all (6.8 GB
    RSS) and called it valid, `render` and `export` died with MemoryError."""
    import h5py
    from click.testing import CliRunner

    from cli.knitbake_cli import main as knitbake
    from tests.helpers import write_full

    path = tmp_path / "p.h5"
    tables = write_full(path)[0]
    name = next(n for n in tables if n.startswith("textures/ao/mip0"))
    with h5py.File(path, "a") as f:
        attrs = dict(f[name].attrs)
        del f[name]
        ds = f.create_dataset(name, shape=shape, dtype="f4", chunks=(256, 256))
        ds.attrs.update(attrs)
    assert path.stat().st_size < 4 << 20
    for command in (["validate", str(path)], ["inspect", str(path)], ["export", str(path), str(tmp_path / "x")]):
        result = CliRunner().invoke(knitbake, command)
        assert result.exit_code == 1 and message in result.output and name in result.output, result.output
        assert len(result.output.strip().splitlines()) == (2 if command[0] == "validate" else 1)  # INVALID + why


def test_a_folder_or_device_given_as_a_file_says_what_it_is(tmp_path):
    """Item 13: a directory or a device given as a scene's `curves` was reported as "file not found"; an empty .exr
    environment as "not a Radiance HDR file"."""
    from data_formats import FormatError
    from data_formats.images import read_image
    from data_formats.scene import load_scene
    from data_formats.yarn_curves import read_yarn_curves

    (tmp_path / "folder.h5").mkdir()
    with pytest.raises(FormatError, match="is a directory, not a regular file"):
        read_yarn_curves(tmp_path / "folder.h5")
    with pytest.raises(FormatError, match="is a character device"):
        read_image("/dev/zero")
    (tmp_path / "empty.exr").write_bytes(b"")
    with pytest.raises(FormatError, match="empty file, expected an OpenEXR or Radiance HDR image"):
        read_image(tmp_path / "empty.exr")
    (tmp_path / "text.exr").write_bytes(b"#?RADIANCE\n")
    with pytest.raises(FormatError, match="not an OpenEXR file"):
        read_image(tmp_path / "text.exr")
    toml = tmp_path / "s.toml"
    toml.write_text(textwrap.dedent("""\
        format = "knit-scene"
        version = "1.0"
        units = "cm"
        [[yarns]]
        curves = "folder.h5"
        yarn = "cotton1"
        [camera]
        position = [0, 0, 5]
        look_at = [0, 0, 0]
        fov_deg = 30
        width = 8
        height = 8
        [[lights]]
        type = "directional"
        direction = [0, 0, 1]
        irradiance = [1, 1, 1]
        """))
    with pytest.raises(FormatError, match=r"yarns\[0\]\.curves = 'folder.h5': .* is a directory"):
        load_scene(toml)


def _with(spec, section, **values):
    return dataclasses.replace(spec, **{section: dataclasses.replace(getattr(spec, section), **values)})


@pytest.mark.parametrize("section, field, value, named", [
    ("geometry", "fiber_pitch", 1e-6, "ply_pitch/fiber_pitch"),
    ("geometry", "ply_pitch", 1e6, "ply_pitch 1e+06"),
    ("flyaways", "hair_density", 1e6, "hair_density 1e+06"),
    ("flyaways", "loop_density", 1e6, "loop_density 1e+06"),
])
def test_legal_extremes_of_a_yarn_are_refused_before_allocating(tmp_path, monkeypatch, section, field, value, named):
    """Item 4: in-range values whose fibers need 50–330 GiB ended in MemoryError tracebacks (after the first stages of
    a bake had run). Now the fiber generator and the bake refuse them in one line naming the field, before any
    allocation or stage, against the memory budget (here 1 GiB)."""
    from data_formats import FormatError
    from knitbake.fibers.procedural_yarn import generate_fibers

    monkeypatch.setenv("KNIT_MAX_MEMORY_BYTES", str(1 << 30))
    spec = _with(load_preset("cotton1"), section, **{field: value})
    refused = rf"would need ~[\d.]+ [GT]iB \(.*{re.escape(named)}.*more than the 1 GiB allowed"
    with pytest.raises(FormatError, match=refused):
        generate_fibers(spec, length=3 * spec.geometry.ply_pitch)
    calls = []
    with pytest.raises(FormatError, match=re.escape(named)):
        bake(spec, tmp_path / "p.h5", quality="draft", on_stage=lambda *a: calls.append(a), use_cache=False)
    assert calls == [] and not (tmp_path / "p.h5").exists()


def test_a_curve_drawn_at_a_tiny_radius_names_the_curve_and_the_radius(monkeypatch):
    """Item 4: a scene radius of 1e-9 scales every curve's length by 4e7 in yarn space (52.8 GiB of fibers); the
    sweep now refuses it naming the curve and the radius."""
    from data_formats import FormatError
    from knitbake.fibers.fiber_sweep import sweep_curve

    monkeypatch.setenv("KNIT_MAX_MEMORY_BYTES", str(1 << 30))
    curves = make_yarn_curves(np.array([[0, 0, 0], [0, 0, 0.5], [0, 0, 1.0]], float), [0, 3], radius=0.04)
    with pytest.raises(FormatError, match=r"curve 0 \(1 long\) drawn at radius 1e-09, [\d.e-]+ × the yarn's [\d.]+: "
                                           r"the fibers of 'cotton1' .* would need"):
        sweep_curve(curves, 0, 0, load_preset("cotton1"), 1e-9)


def test_the_ranges_that_ran_for_minutes_are_closed():
    """Item 4: fibers_per_ply = 5000 (> 180 s of period matching) and render.srbf_count = 256 (> 240 s of fitting)
    are now outside the documented ranges."""
    from data_formats import FormatError
    from data_formats.scene import RENDER_FIELDS
    from data_formats.yarn_spec import dumps_spec, loads_spec

    text = dumps_spec(load_preset("cotton1")).replace("fibers_per_ply = 75", "fibers_per_ply = 5000")
    assert "fibers_per_ply = 5000" in text
    with pytest.raises(FormatError, match=r"fibers_per_ply.*5000.*\[1, 1000\]"):
        loads_spec(text)
    assert RENDER_FIELDS["srbf_count"][2] == 64


def test_arguments_past_int64_are_named_not_tracebacks(tmp_path):
    """Item 8: an OBJ face index above 2^63 raised OverflowError; `bake --seed` >= 2^64 a Numba TypingError after the
    first stage; `--seed -1` a message naming neither option nor value."""
    from click.testing import CliRunner

    from cli.knitbake_cli import main as knitbake
    from data_formats import FormatError
    from data_formats.stitch_mesh import read_obj_stitch_mesh

    obj = tmp_path / "m.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 99999999999999999999999 4\n")
    (tmp_path / "m.labels").write_text("knit\n")
    with pytest.raises(FormatError, match=r"line 5: face 0: vertex 99999999999999999999999 \(1-based\) does not exist"):
        read_obj_stitch_mesh(obj)
    for seed in ("18446744073709551616", "-1"):
        result = CliRunner().invoke(knitbake, ["bake", "cotton1", "-o", str(tmp_path / "p.h5"), "--seed", seed])
        assert result.exit_code == 2 and "'--seed'" in result.output and seed in result.output, result.output
    with pytest.raises(FormatError, match=r"seed = 9223372036854775807: expected an integer in \[0, 2\^62 - 1\]"):
        bake(_small_yarn(), tmp_path / "p.h5", seed=2**63 - 1, on_stage=pytest.fail)
    assert not (tmp_path / "p.h5").exists()


def _group_raising(exc):
    import click

    from cli.common import FriendlyGroup

    @click.group(cls=FriendlyGroup)
    def program():
        pass

    @program.command()
    def run():
        raise exc
    return program


def test_library_errors_show_as_bugs_and_user_errors_as_one_line():
    """Item 9: every ValueError printed as a tidy user error, so a library failure read as the user's mistake. Our
    FormatError (and the file system's OSError) is one line, exit 1; anything else is reported as a bug with its
    traceback, exit 70."""
    from click.testing import CliRunner

    from data_formats import FormatError

    result = CliRunner().invoke(_group_raising(FormatError("a.h5: attr units is 3, expected 'cm'")), ["run"])
    assert result.exit_code == 1 and result.output.strip().endswith("error: a.h5: attr units is 3, expected 'cm'")
    assert len(result.output.strip().splitlines()) == 1
    result = CliRunner().invoke(_group_raising(ValueError("Each lower bound must be strictly less")), ["run"])
    assert result.exit_code == 70, result.output
    assert "Traceback" in result.output and "internal error (a bug of" in result.output
    assert "ValueError: Each lower bound must be strictly less" in result.output.splitlines()[-1]


def test_the_two_library_errors_of_the_probe_are_gone(tmp_path):
    """Item 9's examples: a legal one-row environment map reached scipy's "Each lower bound must be strictly less"
    in the SRBF fit; a pack whose `format` (or a table's `units`) attribute is an array reached numpy's "truth value
    is ambiguous" in `validate`, which never raises, and in read_pack."""
    import h5py

    from data_formats import FormatError
    from data_formats.asset_pack.reader import describe, sniff, validate
    from knitrun.shading.srbf_fit import fit_srbf
    from tests.helpers import write_full

    fit = fit_srbf(np.full((1, 8, 3), 2.0), n_lobes=4)
    assert np.all(np.isfinite(fit.weights)) and fit.relative_l2_error < 1e-3
    for where, key in (("/", "format"), ("dual_scattering/a_b", "units")):
        path = tmp_path / f"{key}.h5"
        write_full(path)
        with h5py.File(path, "a") as f:
            f[where].attrs[key] = np.array([1, 2])
        problems = validate(path)
        assert problems and not any("ambiguous" in p or "unreadable content" in p for p in problems), problems
        assert any(f"{key} is [1, 2]" in p for p in problems), problems
        with pytest.raises(FormatError):
            read_pack(path)
        with pytest.raises(FormatError):
            describe(path)
        assert sniff(path) is (key != "format")


def test_the_smaller_defects(tmp_path):
    """Item 13: `--pack NAME=FILE` with a name no yarn has was ignored; `--only ''` baked everything; a mesh scaled
    by 1e300 printed a numpy RuntimeWarning before failing; an output that is a symlink was replaced by a file."""
    import warnings

    from click.testing import CliRunner

    from cli.knitrun_cli import main as knitrun
    from data_formats import FormatError
    from data_formats.stitch_mesh import read_obj_stitch_mesh
    from knitbake.bake import stages_for

    result = CliRunner().invoke(knitrun, ["render", "examples/scenes/straight_yarn_directional.toml", "--pack",
                                          f"cottn1={tmp_path / 'p.h5'}", "-o", str(tmp_path / "x.png")])
    assert result.exit_code == 1 and "the scene has no yarn 'cottn1' (its yarns: cotton1" in result.output
    with pytest.raises(FormatError, match="--only names no table group"):
        stages_for(_small_yarn(), only=[""])
    obj = tmp_path / "huge.obj"
    obj.write_text("v 0 0 0\nv 1e300 0 0\nv 1e300 1e300 0\nv 0 1e300 0\nf 1 2 3 4\n")
    (tmp_path / "huge.labels").write_text("knit\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(FormatError, match=r"vertex 1: coordinates \(1e\+300, 0.0, 0.0\), expected numbers in "
                                              r"\[-1e\+09, 1e\+09\]"):
            read_obj_stitch_mesh(obj)
    with pytest.raises(FormatError, match=r"frame 0, curve 0, point 1: .* expected numbers in \[-1e\+09, 1e\+09\]"):
        make_yarn_curves(np.array([[0, 0, 0], [2e9, 0, 0]], float), [0, 2])
    target = tmp_path / "real.png"
    target.write_bytes(b"old")
    link = tmp_path / "link.png"
    link.symlink_to(target.name)
    with atomic_path(link) as tmp:
        tmp.write_bytes(b"new")
    assert link.is_symlink() and target.read_bytes() == b"new"


def test_simulate_says_where_a_long_run_spent_its_time(tmp_path):
    """Item 13: `simulate --frames 20000` reported 0.14 ms/frame (the median solve) for a 92 s run. The report now
    holds the whole run's seconds and its parts, and the parts add up to no more than the whole."""
    import json

    from click.testing import CliRunner

    from cli.knitrun_cli import main as knitrun

    mesh, out = tmp_path / "m.h5", tmp_path / "y.h5"
    assert CliRunner().invoke(knitrun, ["pattern", "stockinette", "--rows", "2", "--cols", "2", "-o",
                                        str(mesh)]).exit_code == 0
    result = CliRunner().invoke(knitrun, ["simulate", str(mesh), "--deform", "stretch-x=1.2", "--frames", "150",
                                          "-o", str(out), "--json"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.output[result.output.index("{"):])
    parts = report["seconds"] + report["contact_s"] + report["write_s"]
    assert 0 < report["prepare_s"] + report["curves_s"] <= report["seconds"] <= parts <= report["total_s"]


def _pack_attributes(source):
    """Every attribute of the pack ``source`` as (place, kind, name): place its group or dataset path ("/" the
    root), kind "root", the group's path, "table" or "stderr" (a table's per-entry errors)."""
    import h5py

    from data_formats.asset_pack.schema import STDERR_SUFFIX

    out = []
    with h5py.File(source, "r") as f:
        out += [("/", "root", key) for key in f.attrs]

        def visit(name, obj):
            kind = name if isinstance(obj, h5py.Group) else "stderr" if name.endswith(STDERR_SUFFIX) else "table"
            out.extend((name, kind, key) for key in obj.attrs)

        f.visititems(visit)
    return out


def _each_kind_and_name(attributes):
    """One attribute per (kind, name), spread over the tables: the i-th (kind, name) is taken at the i-th place that
    has it, modulo their count. The reader checks an attribute by its name and its table's schema entry, so this
    reaches every check of every name at a fraction of the exhaustive sweep's cost."""
    places = {}
    for where, kind, key in attributes:
        places.setdefault((kind, key), []).append(where)
    return [(wheres[i % len(wheres)], key) for i, ((kind, key), wheres) in enumerate(places.items())]


def _attributes_as_arrays(tmp_path, pick):
    """Each attribute ``pick`` chooses from a full pack's, replaced by a two-element array, must be reported by
    ``validate`` as a problem, never as "unreadable content" (a numpy or h5py error), or accepted where the schema
    leaves it free; read_pack agrees and raises only FormatError. Returns (checked, refused)."""
    import shutil

    import h5py

    from data_formats import FormatError
    from data_formats.asset_pack.reader import validate
    from tests.helpers import write_full

    source = tmp_path / "source.h5"
    write_full(source)
    path = tmp_path / "pack.h5"
    checked = refused = 0
    for where, key in pick(_pack_attributes(source)):
        shutil.copy(source, path)
        with h5py.File(path, "a") as f:
            f[where].attrs[key] = np.array([1, 2])
        problems = validate(path)
        assert not any("unreadable content" in p for p in problems), (where, key, problems)
        if problems:
            with pytest.raises(FormatError):
                read_pack(path)
        else:  # an attribute the schema leaves free (a description, a baker's note)
            read_pack(path)
        refused += bool(problems)
        checked += 1
    return checked, refused


def test_no_attribute_name_of_a_pack_given_as_an_array_reaches_a_library_error(tmp_path):
    """Item 9, every attribute name: one attribute of each name at each kind of place (root, each group, tables,
    per-entry errors; ``_each_kind_and_name``) replaced by a two-element array is a problem ``validate`` names, never
    "unreadable content"; read_pack raises only FormatError (855 such calls failed before). The sweep over all ~700
    attributes is the slow test below."""
    checked, refused = _attributes_as_arrays(tmp_path, _each_kind_and_name)
    assert checked >= 40 and refused > checked / 2, (checked, refused)


@pytest.mark.slow
def test_no_attribute_of_a_pack_given_as_an_array_reaches_a_library_error(tmp_path):
    """Item 9, every attribute (~2 min): as above at every attribute of the pack, each table's included."""
    checked, refused = _attributes_as_arrays(tmp_path, lambda attributes: [(w, k) for w, _, k in attributes])
    assert checked > 100 and refused > checked / 2, (checked, refused)
