"""Realistic priors: global (K-means palette), local (5x5 variations), human (FaceNet); face region h.

Heavy networks (FaceNet, BiSeNet) live in their own modules and load only when asked for.
"""

from deface.priors.face_region import (
    FaceRegionClassifier,
    SkinClassifierConfig,
    SkinColourClassifier,
    load_face_region_classifier,
)
from deface.priors.global_prior import global_prior, kmeans_palette
from deface.priors.human import HumanPrior, HumanPriorConfig, MissingWeightsError, load_human_prior
from deface.priors.local_prior import local_prior, local_variations, material_local_prior

__all__ = [
    "FaceRegionClassifier",
    "HumanPrior",
    "HumanPriorConfig",
    "MissingWeightsError",
    "SkinClassifierConfig",
    "SkinColourClassifier",
    "global_prior",
    "kmeans_palette",
    "load_face_region_classifier",
    "load_human_prior",
    "local_prior",
    "local_variations",
    "material_local_prior",
]
