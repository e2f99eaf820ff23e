"""The SRBF fit cache (``knitrun.shading.srbf_cache``): a second fit of the same map is read back identical, a
changed map, lobe count or seed misses, a damaged entry is a miss that gets rewritten, and the renderer draws only
lobes of non-zero weight."""

import numpy as np

from knitrun.shading import srbf_cache
from knitrun.shading.builtin_sky import sky_image
from knitrun.shading.srbf_fit import fit_srbf


def test_a_second_fit_is_read_back_identical_and_keys_follow_the_inputs(tmp_path, monkeypatch):
    monkeypatch.setenv("KNIT_CACHE_DIR", str(tmp_path))
    sky = sky_image(32, 64).astype(np.float64)
    first, cached = srbf_cache.cached_fit(sky, 4, 0)
    assert not cached and len(list((tmp_path / "srbf").glob("*.npz"))) == 1
    again, cached = srbf_cache.cached_fit(sky, 4, 0)
    assert cached
    direct = fit_srbf(sky, n_lobes=4, seed=0)
    for name in srbf_cache.FIELDS:
        assert np.array_equal(getattr(again, name), getattr(first, name))
        assert np.array_equal(getattr(again, name), getattr(direct, name))
    keys = {srbf_cache.fit_key(sky, 4, 0), srbf_cache.fit_key(sky * 1.01, 4, 0), srbf_cache.fit_key(sky, 5, 0),
            srbf_cache.fit_key(sky, 4, 1)}
    assert len(keys) == 4
    assert srbf_cache.cached_fit(sky, 4, 0, use_cache=False)[1] is False


def test_a_damaged_entry_is_a_miss_and_is_rewritten(tmp_path, monkeypatch):
    monkeypatch.setenv("KNIT_CACHE_DIR", str(tmp_path))
    sky = sky_image(32, 64).astype(np.float64)
    entry = tmp_path / "srbf" / f"{srbf_cache.fit_key(sky, 3, 0)}.npz"
    entry.parent.mkdir(parents=True)
    entry.write_bytes(b"not a zip file")
    fit, cached = srbf_cache.cached_fit(sky, 3, 0)
    assert not cached and np.all(np.isfinite(fit.weights))
    assert srbf_cache.cached_fit(sky, 3, 0)[1]
