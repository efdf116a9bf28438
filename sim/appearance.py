"""CLIP-like appearance vectors: a shared class part, an instance part, a view part and noise.

An embedding is the unit-normalized sum of unit vectors weighted by the square roots of their
shares: class (common to every instance of a class), instance, view (a smooth function of the
direction the object is seen from) and per-detection noise. Class vectors themselves share a
part common to every class (CLIP image embeddings sit in a narrow cone) and a part common to
their confusable group (a cup looks like a mug). With the default shares, two instances of one
class sit near 0.76 cosine, one instance seen from two views between 0.84 and 0.94, and two
unrelated classes near 0.38 (`sim/scenarios/README.md` gives the reasons).

Random vectors of dimension 64 are not exactly orthogonal: their cosines spread with a standard
deviation of 1/8, which spreads the figures above by a few hundredths, as real ones spread.
"""

from __future__ import annotations

import functools
import math
import zlib
from collections.abc import Sequence

import numpy as np

from sim.detector_settings import AppearanceSpec

# The view part interpolates between this many anchor vectors spread around the object, so
# views 90 degrees apart share nothing of it, and blends in a top-view vector with elevation.
VIEW_ANCHORS = 4


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


class AppearanceModel:
    """Embeddings for objects, phantoms, people and clutter of one scenario."""

    def __init__(self, spec: AppearanceSpec, confusable: Sequence[Sequence[str]] = ()) -> None:
        self.spec = spec
        self.group_of = {label: "+".join(group) for group in confusable for label in group}

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

    def view_vector(self, key: str, direction: np.ndarray) -> np.ndarray:
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
                ((1.0 - share) ** 2, _unit(f"appearance/view/{key}/{first}", dim)),
                (share**2, _unit(f"appearance/view/{key}/{(first + 1) % VIEW_ANCHORS}", dim)),
            ]
        )
        top = _unit(f"appearance/view/{key}/top", dim)
        return _mix([(math.cos(elevation) ** 2, around), (math.sin(elevation) ** 2, top)])

    def embed(
        self,
        key: str,
        label: str,
        direction: np.ndarray,
        rng: np.random.Generator,
        extra_noise: float = 0.0,
    ) -> np.ndarray | None:
        """One detection's embedding of thing `key` of class `label`, seen along `direction`.

        `extra_noise` moves that share from the instance and view parts to noise (a partial mask
        crops the object, so it looks less like itself).
        """
        if self.spec.dim is None:
            return None
        spec, dim = self.spec, self.spec.dim
        personal = spec.instance_share + spec.view_share
        kept = max(0.0, 1.0 - extra_noise / personal) if personal > 0 else 1.0
        noise = rng.standard_normal(dim)
        return _mix(
            [
                (spec.class_share, self.class_vector(label)),
                (spec.instance_share * kept, _unit(f"appearance/instance/{key}", dim)),
                (spec.view_share * kept, self.view_vector(key, direction)),
                (spec.noise_share + personal * (1.0 - kept), noise / np.linalg.norm(noise)),
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
