"""A disk cache of SRBF fits (``knitrun.shading.srbf_fit``), keyed by content: the same environment image (its
float64 pixels after the scene's scale), lobe count and seed give the fit from disk instead of a second fit (1-4 s
at 16 lobes for the built-in sky, more for a large map). The key also hashes ``srbf_fit.py`` itself, so a change to
the method never serves an old fit.

Entries are ``<key>.npz`` files (the ``SRBFFit`` fields) in the ``srbf`` folder of the cache
(``data_formats.cache_folders``), written atomically; an entry that cannot be read is a miss (and is overwritten),
never an error. ``use_cache=False`` neither reads nor writes.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from data_formats.atomic import atomic_path
from data_formats.cache_folders import cache_root
from knitrun.shading import srbf_fit
from knitrun.shading.srbf_fit import SRBFFit, fit_srbf

FIELDS = ("directions", "sharpness", "weights", "relative_l2_error", "irradiance_error", "max_abs_error")


def cache_dir() -> Path:
    return cache_root() / "srbf"


def fit_key(image: np.ndarray, n_lobes: int, seed: int) -> str:
    """The content hash of one fit's inputs and of the fitting code."""
    image = np.ascontiguousarray(image, np.float64)
    digest = hashlib.blake2b(digest_size=16)
    digest.update(Path(srbf_fit.__file__).read_bytes())
    digest.update(repr((image.shape, int(n_lobes), int(seed))).encode())
    digest.update(image.tobytes())
    return digest.hexdigest()


def cached_fit(image, n_lobes: int, seed: int, use_cache: bool = True) -> tuple[SRBFFit, bool]:
    """(fit, from_cache): ``fit_srbf(image, n_lobes=n_lobes, seed=seed)``, from the cache when an entry exists."""
    image = np.ascontiguousarray(image, np.float64)
    if not use_cache:
        return fit_srbf(image, n_lobes=n_lobes, seed=seed), False
    path = cache_dir() / f"{fit_key(image, n_lobes, seed)}.npz"
    try:
        with np.load(path) as entry:
            return SRBFFit(*(entry[name] if entry[name].ndim else float(entry[name]) for name in FIELDS)), True
    except Exception:  # noqa: BLE001  (missing, truncated or foreign entry: a miss, rewritten below)
        pass
    fit = fit_srbf(image, n_lobes=n_lobes, seed=seed)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as f:
                np.savez(f, **{name: getattr(fit, name) for name in FIELDS})
    except OSError:  # a read-only cache folder only costs the next fit
        pass
    return fit, False
