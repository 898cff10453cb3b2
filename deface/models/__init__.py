"""Face models: one interface (:class:`FaceModel`) for ICT-FaceKit (default) and BFM 2017 + AlbedoMM."""

from deface.models.base import AlbedoModel, FaceModel
from deface.models.registry import load_face_model

__all__ = ["AlbedoModel", "FaceModel", "load_face_model"]
