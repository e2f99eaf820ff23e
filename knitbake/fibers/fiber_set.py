"""Explicit fibers as flat arrays: the hand-off from the procedural generator to tessellation and the path tracer.

Conventions
-----------
* Lengths in the yarn spec's unit (centimetres for every preset).
* Yarn space: the yarn axis is +z, the yarn centre line is x = y = 0, and z runs from ``z_start`` to ``z_end``.
* Fiber ``i`` is the polyline ``points[offsets[i]:offsets[i+1]]`` (at least two points) with circular cross-section
  of radius ``radius[i]``.
* ``kind[i]`` is one of ``KIND_REGULAR`` (migration fibers: periodic, tile seamlessly), ``KIND_LOOP`` or
  ``KIND_HAIR`` (flyaways: not periodic). ``ply[i]`` is the ply the fiber belongs to.
"""

from dataclasses import dataclass, field

import numpy as np

KIND_REGULAR = 0
KIND_LOOP = 1
KIND_HAIR = 2
KIND_NAMES = {KIND_REGULAR: "regular", KIND_LOOP: "loop", KIND_HAIR: "hair"}


@dataclass
class FiberSet:
    """Fibers of one yarn as flat arrays (see module docstring for conventions)."""

    points: np.ndarray  # (P, 3) float64
    offsets: np.ndarray  # (F + 1,) int64, offsets[0] == 0, offsets[-1] == P
    radius: np.ndarray  # (F,) float64
    kind: np.ndarray  # (F,) int8
    ply: np.ndarray  # (F,) int16
    z_start: float = 0.0
    z_end: float = 0.0
    info: dict = field(default_factory=dict)  # generator facts: effective pitches, symmetry, counts

    @property
    def n_fibers(self) -> int:
        return int(self.offsets.shape[0] - 1)

    @property
    def n_segments(self) -> int:
        return int(self.points.shape[0] - self.n_fibers)

    def fiber(self, i: int) -> np.ndarray:
        """Points of fiber ``i`` as an (n, 3) view."""
        return self.points[self.offsets[i] : self.offsets[i + 1]]

    def select(self, mask: np.ndarray) -> "FiberSet":
        """A new FiberSet holding only the fibers where ``mask`` is true."""
        idx = np.flatnonzero(mask)
        counts = np.diff(self.offsets)[idx]
        offsets = np.zeros(idx.size + 1, dtype=np.int64)
        np.cumsum(counts, out=offsets[1:])
        if idx.size:
            pts = np.concatenate([self.fiber(i) for i in idx])
        else:
            pts = np.zeros((0, 3))
        return FiberSet(pts, offsets, self.radius[idx].copy(), self.kind[idx].copy(), self.ply[idx].copy(),
                        self.z_start, self.z_end, dict(self.info))
