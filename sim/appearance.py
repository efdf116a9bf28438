"""CLIP-like appearance vectors: a class part, an instance part, a view part and noise.

An embedding is the unit-normalized sum of unit vectors weighted by the square roots of their
shares: class (common to every instance of a class), instance (this object's own look), view (a
smooth function of the direction the object is seen from) and per-detection noise (crop, blur,
background, light). Class vectors themselves share a part common to every class (CLIP image
embeddings sit in a narrow cone) and a part common to their confusable group (a cup looks like a
mug).

Two things make instances of one class overlap, as real SigLIP or CLIP crops of household objects
do (`sim/scenarios/README.md`, "Appearance figures"):

* Distinctiveness. Each look (an object, or a look-alike group of objects) keeps a share d of its
  instance part as its own and gives the rest to its class vector: a plain white mug looks like
  the class, a patterned one like itself. d is drawn per look from a Beta distribution whose
  mean is `distinctiveness`, seeded by the look's name, so it is the same in every run.
* Crop noise. The per-detection noise share is scaled by a log-normal factor per detection
  (`noise_spread`): most crops are clean, some are dominated by background or blur.

Objects of one look-alike group (`look_alike`, two mugs of one set) share one look: their
instance and view parts are the same, only the noise of each detection tells them apart.
`python -m sim.appearance_report` prints the figures these settings give.
"""

from __future__ import annotations

import functools
import math
import zlib
from collections.abc import Sequence

import numpy as np
from scipy.stats import beta

from sim.detector_settings import AppearanceSpec

# The view part interpolates between this many anchor vectors spread around the object, so
# views 90 degrees apart share nothing of it, and blends in a top-view vector with elevation.
VIEW_ANCHORS = 4
# Concentration (a + b) of the Beta distribution of distinctiveness: 4 gives Beta(2, 2) at a
# mean of 0.5, so about a sixth of the looks keep under a quarter of their instance part
# (generic) and a sixth over three quarters (distinctive). Our choice; no published figure.
DISTINCTIVENESS_CONCENTRATION = 4.0


@functools.lru_cache(maxsize=4096)
def _unit(name: str, dim: int) -> np.ndarray:
    """A fixed random unit vector for a name (crc32-seeded: stable across processes)."""
    rng = np.random.default_rng(zlib.crc32(name.encode("utf-8")))
    vector = rng.standard_normal(dim)
    vector /= np.linalg.norm(vector)
    vector.setflags(write=False)
    return vector


def _mix(parts: Sequence[tuple[float, np.ndarray]]) -> np.ndarray:
    """Unit-normalized sum of sqrt(share) * part."""
    total = sum(math.sqrt(share) * part for share, part in parts if share > 0)
    vector = np.asarray(total, dtype=np.float64)
    norm = float(np.linalg.norm(vector))
    return vector / norm if norm > 0 else vector


@functools.lru_cache(maxsize=4096)
def distinctiveness_of(look: str, mean: float) -> float:
    """The share of a look's instance part that is its own: a name-seeded Beta draw of `mean`.

    The draw is the Beta quantile of a uniform seeded by the name, so a look's rank among its
    class stays the same whatever the mean (a sweep moves every look the same way).
    """
    if mean <= 0.0 or mean >= 1.0:
        return min(max(mean, 0.0), 1.0)
    uniform = np.random.default_rng(zlib.crc32(f"appearance/distinct/{look}".encode())).random()
    a, b = mean * DISTINCTIVENESS_CONCENTRATION, (1.0 - mean) * DISTINCTIVENESS_CONCENTRATION
    return float(beta.ppf(uniform, a, b))


class AppearanceModel:
    """Embeddings for objects, phantoms, people and clutter of one scenario."""

    def __init__(self, spec: AppearanceSpec, confusable: Sequence[Sequence[str]] = ()) -> None:
        self.spec = spec
        self.group_of = {label: "+".join(group) for group in confusable for label in group}
        self.look_of = {key: "+".join(group) for group in spec.look_alike for key in group}

    @property
    def dim(self) -> int | None:
        """Vector size, None when the detector sends no embeddings."""
        return self.spec.dim

    def class_vector(self, label: str) -> np.ndarray:
        """The part every instance of a class shares (itself partly shared with other classes)."""
        assert self.spec.dim is not None
        dim, spec = self.spec.dim, self.spec
        group = self.group_of.get(label)
        group_share = spec.group_share if group is not None else 0.0
        parts = [
            (spec.shared_share, _unit("appearance/shared", dim)),
            (1.0 - spec.shared_share - group_share, _unit(f"appearance/class/{label}", dim)),
        ]
        if group is not None:
            parts.append((group_share, _unit(f"appearance/group/{group}", dim)))
        return _mix(parts)

    def view_vector(self, look: str, direction: np.ndarray) -> np.ndarray:
        """Smooth in the (object-frame) direction from the object to the camera."""
        assert self.spec.dim is not None
        dim = self.spec.dim
        azimuth = math.atan2(direction[1], direction[0]) % (2 * math.pi)
        elevation = math.asin(min(1.0, abs(float(direction[2]))))
        position = azimuth / (2 * math.pi) * VIEW_ANCHORS
        first = int(position) % VIEW_ANCHORS
        share = position - int(position)
        around = _mix(
            [
                ((1.0 - share) ** 2, _unit(f"appearance/view/{look}/{first}", dim)),
                (share**2, _unit(f"appearance/view/{look}/{(first + 1) % VIEW_ANCHORS}", dim)),
            ]
        )
        top = _unit(f"appearance/view/{look}/top", dim)
        return _mix([(math.cos(elevation) ** 2, around), (math.sin(elevation) ** 2, top)])

    def look(self, key: str) -> str:
        """The name of what a thing looks like: its look-alike group, else itself."""
        return self.look_of.get(key, key)

    def embed(
        self,
        key: str,
        label: str,
        direction: np.ndarray,
        rng: np.random.Generator,
        extra_noise: float = 0.0,
        place: str | None = None,
    ) -> np.ndarray | None:
        """One detection's embedding of thing `key` of class `label`, seen along `direction`.

        `extra_noise` moves that share from the instance and view parts to noise (a partial mask
        crops the object, so it looks less like itself). `place` names what the crop shows around
        the object (its support; None: its own surroundings): crops taken at one place share
        that context. Two draws per
        call whatever the settings (the noise vector, then the crop's noise factor), so streams
        stay aligned.
        """
        if self.spec.dim is None:
            return None
        spec, dim, look = self.spec, self.spec.dim, self.look(key)
        noise = rng.standard_normal(dim)
        crop = math.exp(spec.noise_spread * float(rng.standard_normal()) - spec.noise_spread**2 / 2)
        distinct = distinctiveness_of(look, spec.distinctiveness)
        own = spec.instance_share * distinct
        personal = own + spec.view_share
        kept = max(0.0, 1.0 - extra_noise / personal) if personal > 0 else 1.0
        # A generic look seen from one side looks like any of its class seen from that side.
        view = _mix(
            [
                (distinct, self.view_vector(look, direction)),
                (1.0 - distinct, self.view_vector(f"class/{label}", direction)),
            ]
        )
        return _mix(
            [
                (spec.class_share + spec.instance_share - own, self.class_vector(label)),
                (own * kept, _unit(f"appearance/instance/{look}", dim)),
                (spec.view_share * kept, view),
                (spec.context_share, _unit(f"appearance/place/{place or key}", dim)),
                (spec.noise_share * crop + personal * (1.0 - kept), noise / np.linalg.norm(noise)),
            ]
        )

    def clutter(self, rng: np.random.Generator) -> np.ndarray | None:
        """What a spurious blob looks like: the common cone plus whatever texture it covers."""
        if self.spec.dim is None:
            return None
        noise = rng.standard_normal(self.spec.dim)
        shared = self.spec.shared_share * self.spec.class_share
        return _mix(
            [
                (shared, _unit("appearance/shared", self.spec.dim)),
                (1.0 - shared, noise / np.linalg.norm(noise)),
            ]
        )
