"""What one bake stage returns (see ``knitbake.bake``)."""

from dataclasses import dataclass, field


@dataclass
class StageResult:
    """Tables of one stage: name → array, its error (per-entry array or scalar), extra dataset attributes, and the
    sample counts recorded in the pack's provenance."""

    tables: dict
    errors: dict
    attrs: dict = field(default_factory=dict)
    counts: dict = field(default_factory=dict)
