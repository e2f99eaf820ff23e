"""The generated part of the asset-pack specification: ``schema_markdown`` renders ``ATTRS``, ``TABLES`` and
``AXES`` as the member tables of ``ASSET_PACK.md`` §11 (a test keeps the document equal to it)."""

from __future__ import annotations

import math

from ..conventions import HALF_PI
from .schema import ATTRS, AXES, DISK_AXIS_NAME, TABLES


def _fmt_angle(x: float) -> str:
    for text, val in (("π/2", HALF_PI), ("π", math.pi)):
        if math.isclose(abs(x), val):
            return ("−" if x < 0 else "") + text
    return f"{x:g}"


def _cell(text: str) -> str:
    """Free text for a table cell: a literal "|" (as in |φ_j − φ_o|) escaped so it does not end the cell."""
    return text.replace("|", "\\|")


def schema_markdown() -> str:
    """The member tables of ASSET_PACK.md, generated from ATTRS and TABLES (a test keeps the two equal)."""
    rows = ["| group | attribute | type | units | meaning |", "|---|---|---|---|---|"]
    for a in ATTRS:
        rows.append(f"| `/{a.group}` | `{a.name}` | {a.kind} | {a.units} | {_cell(a.description)} |")
    rows += ["", "| dataset | shape | axes | units | allowed values | meaning |", "|---|---|---|---|---|---|"]
    for t in TABLES:
        shape = "(" + ", ".join(map(str, t.shape)) + ("," if len(t.shape) == 1 else "") + ")"
        axes = ", ".join(DISK_AXIS_NAME.get(a, a) for a in t.axes) or "—"
        if t.channel_ranges:
            allowed = "channels " + ", ".join(f"[{lo:g}, {hi:g}]" for lo, hi in t.channel_ranges)
        else:
            lo, hi = t.value_range
            allowed = "finite" if lo is None and hi is None else \
                f"{'(−∞' if lo is None else f'[{lo:g}'}, {'∞)' if hi is None else f'{hi:g}]'}"
        if t.vector:
            allowed += f"; ‖ch 0..{t.vector - 1}‖ ≤ 1"
        rows.append(f"| `{t.name}` | {shape} | {axes} | {t.units} | {allowed} | {_cell(t.description)} |")
    rows += ["", "| axis | range | wrap | units | meaning |", "|---|---|---|---|---|"]
    for a in AXES.values():
        if a.sampled:
            rng = f"[{_fmt_angle(a.range[0])}, {_fmt_angle(a.range[1])}]"
            name = DISK_AXIS_NAME.get(a.name, a.name)
            rows.append(f"| `{name}` | {rng} | {a.wrap} | {a.units} | {_cell(a.definition)} |")
        else:
            rows.append(f"| `{a.name}` | index | — | — | {_cell(a.definition)} |")
    return "\n".join(rows)
