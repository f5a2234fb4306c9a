"""Training and evaluation samples from simulated RGB-D views.

ROI samples are what the running labeller would crop: the box of every actor in view (class of
the actor) and the ROI of every segment whose size passes the prior, labelled by the actor pixels
inside it (an actor covering at least half of the ROI gives its class, actors covering at most a
tenth make it ``background``, anything between is ambiguous and left out). Whole views are
labelled ``rack`` when racking fills at least 10 % of the image and ``gate`` when a gate fills
at least 5 %.

The views are textured with crops of *training* photos only (:func:`training_textures`), so no
held-out photo reaches a model through a render.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator

import cv2
import numpy as np
import numpy.typing as npt

from services.labelling_training.datasets import BACKGROUND, Crop, Samples
from services.labelling_training.sim_views import SimView, sample_views, scatter_hall
from services.object_labelling.crops import ROI_PAD_FRACTION, crop_box
from services.object_labelling.range_scan import range_height_scan
from services.object_labelling.retrieval import PriorDatabase, retrieve
from services.object_labelling.segments import segments
from services.simulator.render import Textures
from services.simulator.world import ObjectClass

RACK_FRACTION = 0.10
GATE_FRACTION = 0.05
TEXTURE_CLASSES = {"pallet": ObjectClass.PALLET, "forklift": ObjectClass.FORKLIFT, "human": ObjectClass.PERSON}


def training_textures(crops: Iterable[Crop], *, per_class: int = 24, size_px: int = 64, seed: int = 0
                      ) -> Textures | None:
    """Photo textures for the renderer from ``crops`` (up to ``per_class`` random ones per class).

    Returns None when there are no crops of a texture class (the renderer then uses procedural
    textures).
    """
    by_label: dict[str, list[npt.NDArray[np.uint8]]] = {}
    for crop in crops:
        if crop.label in TEXTURE_CLASSES and min(crop.image.shape[:2]) >= 24:
            by_label.setdefault(crop.label, []).append(crop.image)
    if not by_label:
        return None
    rng = np.random.default_rng(seed)
    atlas: list[npt.NDArray[np.float32]] = []
    by_class: dict[int, npt.NDArray[np.int64]] = {}
    for label, images in sorted(by_label.items()):
        chosen = rng.choice(len(images), size=min(per_class, len(images)), replace=False)
        by_class[int(TEXTURE_CLASSES[label])] = np.arange(len(atlas), len(atlas) + len(chosen))
        atlas += [cv2.resize(images[i], (size_px, size_px), interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0
                  for i in chosen]
    return Textures(np.stack(atlas), by_class)


def simulated_views(halls: Iterable[int], views_per_hall: int, *, textures: Textures | None, seed: int = 0
                    ) -> Iterator[SimView]:
    """``views_per_hall`` views of each scatter hall seeded by ``halls`` (see :mod:`.sim_views`)."""
    rng = np.random.default_rng(seed)
    for hall in halls:
        yield from sample_views(scatter_hall(hall), rng, views_per_hall, textures=textures)


def _roi_label(view: SimView, box: tuple[int, int, int, int]) -> str | None:
    r0, c0, r1, c1 = box
    inside = view.actor_pixels[r0 : r1 + 1, c0 : c1 + 1]
    counts = np.bincount(inside[inside >= 0], minlength=len(view.actor_labels))
    if counts.sum() <= 0.1 * inside.size:
        return BACKGROUND
    best = int(np.argmax(counts))
    return view.actor_labels[best] if counts[best] >= 0.5 * inside.size else None


def view_samples(view: SimView, source: str, priors: PriorDatabase, *, roi_classes: tuple[str, ...]
                 ) -> tuple[list[Crop], dict[str, int]]:
    """ROI crops of one view (actors in view and size-plausible segments) and its whole-image labels."""
    crops = [Crop(crop_box(view.rgb, obj.box, pad_fraction=ROI_PAD_FRACTION), obj.label, source)
             for obj in view.objects]
    for proposal in retrieve(segments(range_height_scan(view.depth_mm, view.intrinsics, view.plane)), priors,
                             view.intrinsics):
        if not any(name in roi_classes for name in proposal.distances):
            continue
        label = _roi_label(view, proposal.box)
        if label is not None:
            crops.append(Crop(crop_box(view.rgb, proposal.box, pad_fraction=ROI_PAD_FRACTION), label, source))
    return crops, {"rack": int(view.rack_fraction >= RACK_FRACTION), "gate": int(view.gate_fraction >= GATE_FRACTION)}


def sim_samples(views: Iterable[SimView], priors: PriorDatabase, *, roi_classes: tuple[str, ...],
                source_prefix: str = "sim") -> Samples:
    """:class:`Samples` of simulated views (each view its own source, named ``<prefix>-<index>``)."""
    crops: list[Crop] = []
    images: list[npt.NDArray[np.uint8]] = []
    labels: dict[str, list[int]] = {"rack": [], "gate": []}
    sources: list[str] = []
    for k, view in enumerate(views):
        source = f"{source_prefix}-{k}"
        view_crops, scene = view_samples(view, source, priors, roi_classes=roi_classes)
        crops += view_crops
        images.append(view.rgb)
        sources.append(source)
        for name, value in scene.items():
            labels[name].append(value)
    return Samples(crops, images, {name: np.array(v, dtype=np.int64) for name, v in labels.items()}, sources)
