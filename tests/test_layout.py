"""The package layout's rules, read from the source with ``ast`` (no module is imported to check them):

* the dependency rule data_formats ← knitrun ← knitbake ← cli: a package imports only itself and the packages to its
  left (every import counts, including those inside functions);
* no import cycle between modules (module-level imports, which run at import time);
* no module imports another module's private (underscore) name;
* the ablation names and the command-line programs load without Numba (``knitrun/render/ablations.py``).
"""

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
LAYERS = ("data_formats", "knitrun", "knitbake", "cli")  # each may import the ones before it


def modules():
    """Dotted name → source path of every module of the four packages."""
    out = {}
    for package in LAYERS:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


MODULES = modules()


def imports(name, path):
    """(imported module, names imported from it, at module level?) for every import statement of a module."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    top = {id(node) for node in tree.body}
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(a.name, [], id(node) in top) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[:len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            names = [a.name for a in node.names]
            found.append((base, names, id(node) in top))
            # `from package import module` imports that module too
            found += [(f"{base}.{n}", [], id(node) in top) for n in names if f"{base}.{n}" in MODULES]
    return found


def own(module):
    """The module of ours an import names (its longest known prefix), or None for a third-party one."""
    while module and module not in MODULES:
        module = module.rpartition(".")[0]
    return module or None


def test_the_scan_finds_every_package_and_resolves_relative_imports():
    assert {m.split(".")[0] for m in MODULES} == set(LAYERS) and len(MODULES) > 60
    targets = {t for t, _, _ in imports("data_formats.asset_pack", MODULES["data_formats.asset_pack"])}
    assert "data_formats.asset_pack.reader" in targets and "data_formats.conventions" in targets


def test_every_import_follows_the_dependency_rule():
    bad = []
    for name, path in MODULES.items():
        layer = LAYERS.index(name.split(".")[0])
        for target, _, _ in imports(name, path):
            ours = own(target)
            if ours is not None and LAYERS.index(ours.split(".")[0]) > layer:
                bad.append(f"{name} imports {target}")
    assert bad == [], "imports against data_formats ← knitrun ← knitbake ← cli:\n" + "\n".join(bad)


def test_no_import_cycle_between_modules():
    graph = {name: {own(t) for t, _, top in imports(name, path) if top and own(t) not in (None, name)}
             for name, path in MODULES.items()}
    state, cycles = {}, []

    def visit(node, stack):
        state[node] = "open"
        for nxt in sorted(graph[node]):
            if state.get(nxt) == "open":
                cycles.append(" → ".join(stack[stack.index(nxt):] + [nxt]))
            elif nxt not in state:
                visit(nxt, stack + [nxt])
        state[node] = "done"

    for node in sorted(graph):
        if node not in state:
            visit(node, [node])
    assert cycles == [], "import cycles:\n" + "\n".join(cycles)


def test_no_module_imports_another_modules_private_names():
    bad = []
    for name, path in MODULES.items():
        for target, names, _ in imports(name, path):
            if own(target) not in (None, name):
                bad += [f"{name} imports {target}.{n}" for n in names if n.startswith("_") and n != "__version__"]
    assert bad == [], "\n".join(bad)


@pytest.mark.parametrize("module", ["knitrun.render.ablations", "cli.knitrun_cli", "cli.knitbake_cli"])
def test_loads_without_numba(module):
    code = f"import sys, {module}; sys.exit('numba' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], cwd=ROOT).returncode == 0, f"{module} imports numba"


def test_the_kernel_cache_folder_follows_every_source(tmp_path):
    """Numba checks only a kernel's own file, so the cache folder is keyed by all sources: an edit to any module
    (a callee in another file) moves it, the same sources keep it."""
    from data_formats.numba_setup import PACKAGES, sources_hash

    for package in PACKAGES:
        (tmp_path / package / "sub").mkdir(parents=True)
        (tmp_path / package / "sub" / "m.py").write_text("x = 1\n")
    first = sources_hash(tmp_path)
    assert sources_hash(tmp_path) == first
    (tmp_path / "knitrun" / "sub" / "m.py").write_text("x = 2\n")
    assert sources_hash(tmp_path) != first
    assert sources_hash() != first and len(sources_hash()) == 16


def test_settings_that_change_the_machine_code_get_their_own_cache_folder():
    """Numba's cache key ignores settings such as ``NUMBA_ENABLE_PROFILING``: kernels compiled under them must not
    land in the folder that normal runs load from."""
    from data_formats.numba_setup import cache_folder_name, sources_hash

    assert cache_folder_name({}) == sources_hash()
    profiled = cache_folder_name({"NUMBA_ENABLE_PROFILING": "1"})
    assert profiled.startswith(sources_hash() + "-") and profiled != cache_folder_name({"NUMBA_OPT": "0"})
    assert cache_folder_name({"NUMBA_ENABLE_PROFILING": "1", "UNRELATED": "x"}) == profiled
    code = ("import os; import data_formats; from data_formats.numba_setup import sources_hash; "
            f"assert os.path.basename(os.environ['NUMBA_CACHE_DIR']) == {profiled!r} != sources_hash()")
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    subprocess.run([sys.executable, "-c", code], check=True, env={**env, "NUMBA_ENABLE_PROFILING": "1"})


def test_kernels_use_the_keyed_cache_folder_even_after_a_plain_numba_import():
    """A script that imports numba before the toolchain (``benchmarks/bench_render.py`` does) still caches kernels
    in the keyed folder, not in ``__pycache__`` beside the sources, where a stale callee would be loaded."""
    code = ("import numba, os; import knitrun.render.strip_shading; from numba.core import config; "
            "from data_formats.numba_setup import sources_hash; "
            "assert config.CACHE_DIR == os.environ['NUMBA_CACHE_DIR'] and config.CACHE_DIR.endswith(sources_hash())")
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    subprocess.run([sys.executable, "-c", code], check=True, env=env)
