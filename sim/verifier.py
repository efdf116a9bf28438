"""The simulated VLM verifier of a rollout (sections 3.2 and 3.4), answering from the world's truth.

It answers the two questions the paper puts to a VLM:

- coarse-stage verification: a fixture hypothesis the consensus gate sent to verification
  (near-threshold or class-conflicting) is confirmed, with the class of the true fixture under
  its center, or rejected when no true fixture stands there (a spurious cluster: a rug, a
  stretch of wall);
- parent verification at an inspection capture: is there a fixture of the target's class at
  its place.

"Under its center" is the footprint of a true fixture, grown by `reach_m` (a fixture track's
center is an EMA of partial clusters), the nearest such fixture when two qualify. Each answer
is wrong with probability `error_rate`: a confirmation turns into a rejection and back (the
class named then is the track's own). The draw is a hash of the rollout's seed and the
question (the track, or the capture), not a shared random stream, so the answers do not depend
on the order in which they are asked, and the in-process and HTTP memories get the same ones.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

from api_schema import VerdictIn
from sim.world import Box

if TYPE_CHECKING:
    from sim.memories import Memory, VerdictOutcome

SOURCE = "simulated-vlm"  # the verdicts' `source`


@dataclass(frozen=True)
class Answer:
    """One answer: confirm or not, the class named, and whether the error draw flipped it."""

    confirm: bool
    label: str
    truth_id: str | None  # the true fixture under the track, if any
    wrong: bool


def gap_to_footprint(x: float, y: float, box: Box) -> float:
    """Planar distance from (x, y) to the (turned) box's footprint, 0 over it."""
    dx, dy = x - box.center[0], y - box.center[1]
    cos_yaw, sin_yaw = math.cos(box.yaw), math.sin(box.yaw)
    along, across = cos_yaw * dx + sin_yaw * dy, -sin_yaw * dx + cos_yaw * dy
    out_along = max(abs(along) - box.size[0] / 2, 0.0)
    out_across = max(abs(across) - box.size[1] / 2, 0.0)
    return math.hypot(out_along, out_across)


class SimulatedVerifier:
    """Answers from the true fixtures, wrong with probability `error_rate` (seeded by `seed`)."""

    def __init__(
        self,
        fixtures: Sequence[Box],
        seed: int,
        error_rate: float,
        taxonomy: Sequence[str],
        reach_m: float = 0.3,
    ) -> None:
        if not 0.0 <= error_rate <= 1.0:
            raise ValueError(f"verifier error rate {error_rate} is not in [0, 1]")
        self.fixtures = tuple(fixtures)
        self.seed = seed
        self.error_rate = error_rate
        self.taxonomy = frozenset(taxonomy)
        self.reach_m = reach_m

    def truth_at(self, x: float, y: float) -> Box | None:
        """The true fixture whose footprint, grown by `reach_m`, holds (x, y); the nearest."""
        near = [
            (gap_to_footprint(x, y, box), math.hypot(x - box.center[0], y - box.center[1]), box)
            for box in self.fixtures
        ]
        held = [entry for entry in near if entry[0] <= self.reach_m]
        if not held:
            return None
        return min(held, key=lambda entry: (entry[0], entry[1], entry[2].id))[2]

    def coarse(self, track_id: str, label: str, center: Sequence[float]) -> Answer:
        """Coarse-stage verification of a fixture hypothesis: the true class there, if any."""
        truth = self.truth_at(center[0], center[1])
        right = truth is not None and truth.label in self.taxonomy
        named = truth.label if right and truth is not None else label
        wrong = self._wrong(f"coarse/{track_id}")
        truth_id = None if truth is None else truth.id
        if wrong:
            return Answer(not right, label, truth_id, True)
        return Answer(right, named, truth_id, False)

    def parent(self, capture_id: str, label: str, center: Sequence[float]) -> bool:
        """Parent verification at a capture: a true fixture of class `label` at `center`."""
        truth = self.truth_at(center[0], center[1])
        right = truth is not None and truth.label == label
        return right != self._wrong(f"parent/{capture_id}")

    def _wrong(self, question: str) -> bool:
        """Whether this question's answer is wrong: a uniform draw hashed from seed and question."""
        if self.error_rate <= 0.0:
            return False
        digest = hashlib.sha256(f"{self.seed}:{question}".encode()).digest()
        uniform = int.from_bytes(digest[:8], "big") / 2**64
        return uniform < self.error_rate


# -- the closed loop asks it, through the memory a robot talks to ----------------------------


@dataclass(frozen=True)
class VerdictRecord:
    """One coarse-stage verdict the simulated verifier gave, and what the memory made of it."""

    track_id: str
    asked_label: str  # the track's label when asked
    verdict: str  # confirm or reject
    label: str  # the class the verdict names
    truth_id: str | None  # the true fixture under the track, if any
    wrong: bool  # the error draw flipped the answer
    outcome: VerdictOutcome  # the track's state after it, or the memory's refusal


def answer_verifications(verifier: SimulatedVerifier | None, memory: Memory) -> list[VerdictRecord]:
    """Coarse-stage verification (section 3.2): one verdict per fixture in the memory's
    verification queue, about the frame it names to crop (its best frame)."""
    records: list[VerdictRecord] = []
    if verifier is None:
        return records
    for pending in memory.pending_verifications():
        answer = verifier.coarse(pending.track_id, pending.label, pending.center)
        verdict: Literal["confirm", "reject"] = "confirm" if answer.confirm else "reject"
        body = VerdictIn(
            verdict=verdict, label=answer.label, source=SOURCE, frame_id=pending.best_frame
        )
        outcome = memory.verify(pending.track_id, body)
        records.append(
            VerdictRecord(
                pending.track_id,
                pending.label,
                verdict,
                answer.label,
                answer.truth_id,
                answer.wrong,
                outcome,
            )
        )
    return records


def parent_verified(
    verifier: SimulatedVerifier | None, memory: Memory, capture_id: str, fixture_id: str
) -> bool | None:
    """Parent verification at the capture (section 3.4): the target's class at its place."""
    if verifier is None:
        return None
    fixture = memory.track(fixture_id)
    if fixture is None:
        return None  # the memory no longer knows it: the capture is refused anyway
    return verifier.parent(capture_id, fixture.label, fixture.center)
