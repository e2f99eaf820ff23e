"""Asset pack: everything baked for one yarn type, in one HDF5 file (``format = "knit-asset-pack"``).

The written specification a third-party renderer needs is ``ASSET_PACK.md`` (in ``data_formats/``, next to this
package). In short:

* Root attrs ``format``, ``schema_version`` ("major.minor"). A reader MUST refuse an unknown major version and
  accept a higher minor one (ignoring members it does not know).
* Groups ``/yarn``, ``/provenance``, ``/fiber_bcsdf`` hold attributes only (``ATTRS``).
* Every baked table is OPTIONAL (``TABLES``): one float32 dataset per table, self-describing axes
  (``axes``, ``axis{i}_range``, ``axis{i}_wrap``, ``axis{i}_units``, ``axis{i}_samples``), sampled at cell centres
  of a uniform grid, and an error bar (``error_estimate``, ``error_kind``, ``error_statistic``, and a same-shape
  ``<name>_stderr`` dataset where per-entry errors exist).

``ATTRS`` and ``TABLES`` are the single schema: the writer, the reader and the validator all check through the
same functions (``attr_problem``, ``table_meta_problems``, ``shape_problems``, ``numeric_problems``), so what
one accepts the others accept.

Modules: ``schema`` (constants, axes, tables, attributes, ``resolve_table``), ``checks`` (the shared checks),
``pack`` (the in-memory ``AssetPack``), ``writer`` (``write_pack``), ``reader`` (``read_pack``, ``validate``,
``sniff``, ``describe``) and ``spec_markdown`` (``schema_markdown``). This package re-exports their public names;
the grid rule ``cell_centres`` is ``data_formats.conventions``'.
"""

from ..conventions import cell_centres
from .pack import AssetPack, AxisInfo, TableInfo
from .reader import describe, read_pack, sniff, validate
from .schema import (ATTRS, AXES, COMPRESS_BYTES, DEFAULT_ERROR_KIND, FORMAT_NAME, GROUPS, IM_AXES, MAX_MIP_LEVELS,
                     SCHEMA_MAJOR, SCHEMA_MINOR, SCHEMA_VERSION, STDERR_SUFFIX, TABLE_DTYPE, TABLES, WRAPS, AttrSpec,
                     Axis, TableSpec, resolve_table)
from .spec_markdown import schema_markdown
from .writer import write_pack

__all__ = [
    "ATTRS", "AXES", "COMPRESS_BYTES", "DEFAULT_ERROR_KIND", "FORMAT_NAME", "GROUPS", "IM_AXES", "MAX_MIP_LEVELS",
    "SCHEMA_MAJOR", "SCHEMA_MINOR", "SCHEMA_VERSION", "STDERR_SUFFIX", "TABLE_DTYPE", "TABLES", "WRAPS",
    "AssetPack", "AttrSpec", "Axis", "AxisInfo", "TableInfo", "TableSpec",
    "cell_centres", "describe", "read_pack", "resolve_table", "schema_markdown", "sniff", "validate", "write_pack",
]
