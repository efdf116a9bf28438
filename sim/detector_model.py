"""The realistic detector: what the evaluation's streams, the robot and the demo all see.

Per frame, in a fixed order: every latent of the detector's luck advances; each visible object
is reported with its viewpoint recall (`sim.detectability`), its mask bleeds onto its support,
leaks, or covers only a part or is split in two (`sim.masks`), its label may flicker to a
confusable class or be confused with any other (its class scores then often confidently wrong),
and its embedding is CLIP-like, overlapping other instances of its class (`sim.appearance`);
people are reported when the scenario says as what; phantoms (posters, reflections) are
reported from their cone of views; fixtures go through the open-vocabulary segmenter
(`sim.fixture_segmenter`: per-view scores, merged, split and hallucinated masks); and random
false-positive blobs land on visible surfaces (`sim.spurious`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from sim.appearance import AppearanceModel
from sim.detectability import DetectorLuck, ViewFactors, box_view_factors, recall_probability
from sim.detector import SimDetection
from sim.detector_settings import DetectorSpec, correlation_per_frame
from sim.fixture_segmenter import FixtureSegmenter, fixture_luck_keys, over_footprint
from sim.masks import bleed, leak, partial, split
from sim.phantoms import PHANTOM_PREFIX, phantom_view
from sim.render import Render
from sim.scenario_spec import Scenario
from sim.spurious import false_positives, spurious_sites
from sim.world import Box, World

PERSON_PREFIX = "person-"  # object_id of a person detection: not a tracked object
# A partial mask crops the object: this share of its instance and view parts turns into noise.
PARTIAL_APPEARANCE_LOSS = 0.08
SUPPORT_TOLERANCE_M = 0.03  # an object rests on a fixture whose top is this close to its bottom


def support_of(box: Box, fixtures: Sequence[Box]) -> str:
    """The fixture an object stands on (its top within 3 cm of the object's bottom, the object's
    center over its footprint), else "floor": what a crop of the object shows around it."""
    bottom = box.center[2] - box.size[2] / 2
    for fixture in fixtures:
        near = abs(fixture.top_z - bottom) < SUPPORT_TOLERANCE_M
        if near and over_footprint(box.center[0], box.center[1], fixture):
            return fixture.id
    return "floor"


def _object_frame_direction(box: Box, eye: np.ndarray) -> np.ndarray:
    """Unit vector from the box to the camera, in the box's own (yawed) axes."""
    offset = eye - np.asarray(box.center, dtype=np.float64)
    offset /= max(float(np.linalg.norm(offset)), 1e-9)
    cos_yaw, sin_yaw = math.cos(box.yaw), math.sin(box.yaw)
    return np.array(
        [cos_yaw * offset[0] + sin_yaw * offset[1], -sin_yaw * offset[0] + cos_yaw * offset[1],
         offset[2]]
    )  # fmt: skip


class RealisticDetector:
    """The detector of one run: it carries the latent luck of every thing from frame to frame."""

    def __init__(self, scenario: Scenario, rng: np.random.Generator) -> None:
        self.spec: DetectorSpec = scenario.detector
        self.labels = scenario.object_labels
        groups = self.spec.labels.confusable
        self.partners = {
            label: [other for other in group if other != label]
            for group in groups
            for label in group
        }
        self.appearance = AppearanceModel(self.spec.appearance, groups)
        self.detected_as = {person.id: person.detected_as for person in scenario.people}
        fixture_boxes = [spec.box() for spec in scenario.fixtures]
        self.segmenter = None
        keys = [f"object/{spec.id}" for spec in scenario.objects]
        keys += [f"person/{person.id}" for person in scenario.people]
        keys += [f"phantom/{phantom.id}" for phantom in self.spec.phantoms]
        if self.spec.fixtures is not None:
            # The hallucination sites come first in the run's draws, before any latent.
            sites = spurious_sites(
                scenario.room_size,
                fixture_boxes,
                [spec.box() for spec in scenario.occluders],
                self.spec.fixtures.spurious_per_m2,
                rng,
            )
            self.segmenter = FixtureSegmenter(self.spec.fixtures, groups, fixture_boxes, sites)
            keys += fixture_luck_keys(fixture_boxes, self.segmenter.pairs, len(sites))
        correlation = correlation_per_frame(
            self.spec.recall.miss_correlation_s, scenario.frame_period
        )
        self.luck = DetectorLuck(keys, correlation, rng)

    def detect(
        self,
        render: Render,
        world: World,
        frame_index: int,
        rng: np.random.Generator,
        input_scale: float = 1.0,
    ) -> list[SimDetection]:
        """Everything the detector reports in one frame.

        `input_scale` < 1 is the far-range detector of a moving robot's keyframes
        (`far_range_input_scale`): it sees the frame downsampled, so an object's pixel area
        counts `input_scale^2` of its pixels (small, far objects go unreported).
        """
        self.luck.step(rng)
        detections = self._objects(render, world, rng, input_scale**2)
        detections += self._people(render, world, rng)
        detections += self._phantoms(render, rng)
        if self.segmenter is not None:
            detections += self.segmenter.detect(render, world, rng, self.luck)
        for blob in false_positives(
            render,
            world,
            rng,
            rate=self.spec.false_positives_per_frame,
            labels=self.labels,
            frame_index=frame_index,
            score=self.spec.score,
            embedding_dim=self.appearance.dim,
        ):
            detections.append(dataclasses.replace(blob, embedding=self.appearance.clutter(rng)))
        return detections

    # -- objects ------------------------------------------------------------------------------

    def _objects(
        self, render: Render, world: World, rng: np.random.Generator, area_scale: float = 1.0
    ) -> list[SimDetection]:
        visible = np.bincount(render.instance.ravel() + 1, minlength=len(world.objects) + 1)[1:]
        surfaces = render.fixture_instance >= 0
        eye = render.pose[:3, 3]
        detections: list[SimDetection] = []
        for index, box in enumerate(world.objects):
            pixels = int(visible[index] * area_scale)  # what the detector's input holds
            if pixels < self.spec.min_visible_pixels:
                continue
            factors = box_view_factors(box, int(visible[index]), render.camera, render.pose)
            factors = dataclasses.replace(factors, pixels=pixels)
            if not self._reported(f"object/{box.id}", factors):
                continue
            masks, cropped = self._object_masks(render.instance == index, surfaces, rng)
            direction = _object_frame_direction(box, eye)
            place = support_of(box, world.fixtures)
            for mask in masks:
                loss = PARTIAL_APPEARANCE_LOSS if cropped else 0.0
                embedding = self.appearance.embed(box.id, box.label, direction, rng, loss, place)
                label = self._reported_label(box.label, rng)
                detections.append(
                    SimDetection(
                        box.id,
                        label,
                        self.spec.score,
                        mask,
                        embedding,
                        class_scores=self.class_scores(box.label, label, rng),
                    )
                )
        return detections

    def _reported(self, key: str, factors: ViewFactors, scale: float = 1.0) -> bool:
        return self.luck.passes(key, scale * recall_probability(factors, self.spec.recall))

    def _object_masks(
        self, mask: np.ndarray, surfaces: np.ndarray, rng: np.random.Generator
    ) -> tuple[list[np.ndarray], bool]:
        """The masks a segmenter returns for one object, and whether they crop it."""
        spec = self.spec.masks
        # A fixed number of draws per reported object keeps the stream aligned across settings.
        spill, spill_px = (
            rng.random(),
            int(rng.integers(spec.support_bleed_px[0], spec.support_bleed_px[1] + 1)),
        )
        cut, keep, angle = rng.random(), rng.uniform(*spec.partial_keep), rng.uniform(0, math.pi)
        if spill < spec.support_bleed_rate:
            mask = bleed(mask, surfaces, spill_px)
        mask = leak(mask, spec.boundary_leak_px)
        masks, cropped = [mask], False
        if cut < spec.split_rate:
            masks, cropped = list(split(mask, angle)), True
        elif cut < spec.split_rate + spec.partial_rate:
            masks, cropped = [partial(mask, keep, angle)], True
        return [m for m in masks if m.sum() >= self.spec.min_visible_pixels], cropped

    def _reported_label(self, label: str, rng: np.random.Generator) -> str:
        """The label a detection carries: its own, a confusable partner's, or rarely any other."""
        spec = self.spec.labels
        draw, pick = rng.random(), rng.random()
        partners = self.partners.get(label, [])
        if partners and draw < spec.flicker:
            return partners[int(pick * len(partners))]
        others = [other for other in self.labels if other != label]
        if others and spec.flicker <= draw < spec.flicker + spec.confusion:
            return others[int(pick * len(others))]
        return label

    def class_scores(
        self, true_label: str, reported: str, rng: np.random.Generator
    ) -> dict[str, float] | None:
        """An open-vocabulary detector's scores of the confusable classes (OWL-ViT and Grounding
        DINO score every prompt): the reported class first, its group close behind. Both the
        true class and its confusions score high, so the scores hint at, not decide, the class.

        A label confused with a class outside the true class's group keeps the true group in
        its scores only `labels.confusion_keeps_truth` of the time; otherwise the detector is
        confidently wrong and scores the reported class's own group, as for an object of it.
        """
        keep = rng.random()  # drawn for every detection, so the stream stays aligned
        group = [true_label, *self.partners.get(true_label, [])]
        if reported not in group and keep >= self.spec.labels.confusion_keeps_truth:
            group = [reported, *self.partners.get(reported, [])]
        if len(group) < 2:
            return None
        scores = {reported: self.spec.score}
        for other in group:
            if other != reported:
                scores[other] = round(self.spec.score - float(rng.uniform(0.03, 0.25)), 3)
        return dict(sorted(scores.items(), key=lambda item: -item[1]))

    # -- people and phantoms ------------------------------------------------------------------

    def _people(self, render: Render, world: World, rng: np.random.Generator) -> list[SimDetection]:
        if render.occluder_instance is None:
            return []
        visible = np.bincount(
            render.occluder_instance.ravel() + 1, minlength=len(world.occluders) + 1
        )[1:]
        detections = []
        for index, box in enumerate(world.occluders):
            if box.kind != "person" or visible[index] < self.spec.min_visible_pixels:
                continue
            detected_as = self.detected_as.get(box.id)
            if detected_as is None:
                continue  # a walker the detector is not prompted for
            factors = box_view_factors(box, int(visible[index]), render.camera, render.pose)
            if not self._reported(f"person/{box.id}", factors):
                continue
            mask = leak(render.occluder_instance == index, self.spec.masks.boundary_leak_px)
            direction = _object_frame_direction(box, render.pose[:3, 3])
            embedding = self.appearance.embed(box.id, detected_as, direction, rng)
            detections.append(
                SimDetection(
                    f"{PERSON_PREFIX}{box.id}", detected_as, self.spec.score, mask, embedding
                )
            )
        return detections

    def _phantoms(self, render: Render, rng: np.random.Generator) -> list[SimDetection]:
        detections = []
        for phantom in self.spec.phantoms:
            view = phantom_view(phantom, render)
            if view is None or view.factors.pixels < self.spec.min_visible_pixels:
                continue
            if not self._reported(f"phantom/{phantom.id}", view.factors, phantom.recall):
                continue
            embedding = self.appearance.embed(phantom.id, phantom.label, view.direction, rng)
            detections.append(
                SimDetection(
                    f"{PHANTOM_PREFIX}{phantom.id}",
                    phantom.label,
                    self.spec.score,
                    view.mask,
                    embedding,
                )
            )
        return detections
