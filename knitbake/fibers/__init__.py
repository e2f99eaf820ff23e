"""Explicit fibers: the procedural yarn generator, the fiber set, fibers swept along yarn curves, tessellation into
tubes."""
