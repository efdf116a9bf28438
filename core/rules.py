"""Update rules: what decide() does with the evidence. The defaults are the paper's (section 3.3).

Baselines and ablations are other instances of this one object handed to the same loop
(never `if ablation == ...` in the core). Rules that are plain numbers (confirmation batches,
miss increments) stay in `Params`; these are the ones that change a mechanism.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal


@dataclass(frozen=True)
class UpdateRules:
    """The mechanisms decide() applies; each flag names the paper component it switches."""

    # The geometric visibility gate: a box sample must have valid depth in its window and be
    # unoccluded. Without it, being in range and inside the image is enough for a miss.
    visibility_gate: bool = True
    # Persistent identity: removed tracks and long-unseen tracks take part in association.
    # None keeps every identity forever; a number of seconds forgets tracks unseen for longer,
    # and removed tracks never come back.
    identity_memory_s: float | None = None
    # Removal and demotion at all (append-only memories never resolve a disappearance).
    removal: bool = True
    # What a miss needs: the box observable and unoccluded ("visible", the paper's gate), or
    # depth showing free space at the object's own points ("free_space", DynaMem's per-voxel
    # clearing rule: the samples of its latest observed box, at least half of them free).
    miss_evidence: Literal["visible", "free_space"] = "visible"


DEFAULT_RULES = UpdateRules()
"""Every mechanism of section 3.3 on, as the paper writes it. Both profiles of
`core.profiles` run these rules; what we added beside the paper are parameters of
`core.params`, each with a value that restores the paper's rule."""
