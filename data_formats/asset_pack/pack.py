"""The in-memory asset pack ``read_pack`` returns: ``AssetPack`` (attribute groups, every table's metadata, the
loaded tables and their per-entry errors) with ``TableInfo`` and ``AxisInfo`` describing each table and axis."""

from __future__ import annotations

import dataclasses

from ..conventions import cell_centres


@dataclasses.dataclass
class AxisInfo:
    name: str
    size: int
    range: tuple | None = None  # (lo, hi) for sampled axes; samples are cell centres
    wrap: str | None = None
    units: str = ""
    definition: str = ""

    @property
    def samples(self):
        return None if self.range is None else cell_centres(self.range[0], self.range[1], self.size)


@dataclasses.dataclass
class TableInfo:
    """Metadata of one table present in a pack (read without touching its data)."""

    name: str
    shape: tuple
    units: str
    axes: list
    error_estimate: float
    error_kind: str
    error_statistic: str
    has_stderr: bool
    attrs: dict


@dataclasses.dataclass
class AssetPack:
    """A read pack. ``tables``/``stderr`` hold only the datasets asked for; ``info`` describes every table."""

    path: str
    schema_version: str
    yarn: dict
    provenance: dict
    fiber_bcsdf: dict
    info: dict
    tables: dict
    stderr: dict

    def mip_chain(self, base: str) -> list:
        """The loaded mip levels of texture ``base`` (e.g. ``textures/normal``), level 0 first."""
        out = []
        while f"{base}/mip{len(out)}" in self.tables:
            out.append(self.tables[f"{base}/mip{len(out)}"])
        return out
