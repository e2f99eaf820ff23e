"""Fixtures shared by the test modules (plain shared data and builders are in ``helpers.py``)."""

import dataclasses

import pytest

from data_formats.yarn_spec import load_preset
from knitbake.bake import bake
from tests.helpers import TINY


@pytest.fixture(scope="session")
def pack(tmp_path_factory):
    """A tiny asset pack of cotton1 (15 fibers per ply, every stage at ``TINY`` settings, seed 1, no stage cache)
    for the renderer's tests; read-only."""
    spec = load_preset("cotton1")
    spec = dataclasses.replace(spec, geometry=dataclasses.replace(spec.geometry, fibers_per_ply=15))
    out = tmp_path_factory.mktemp("pack") / "cotton1.h5"
    bake(spec, out, overrides=TINY, seed=1, use_cache=False)
    return out
