"""Light decoupling: the light-mask field f, the face-region field g, ACE, and image composition."""

from deface.decouple.ace import ace_select, light_areas, renormalise
from deface.decouple.compose import compose_face, composite, face_region_mask
from deface.decouple.coords import frame_time, pixel_coordinates, video_coordinates
from deface.decouple.fields import FaceRegionField, LightMaskField, fourier_features

__all__ = [
    "FaceRegionField",
    "LightMaskField",
    "ace_select",
    "compose_face",
    "composite",
    "face_region_mask",
    "fourier_features",
    "frame_time",
    "light_areas",
    "pixel_coordinates",
    "renormalise",
    "video_coordinates",
]
