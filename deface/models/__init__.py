"""Face models: one interface (:class:`FaceModel`) for ICT-FaceKit (embedded default) and BFM 2017 + AlbedoMM."""

from deface.models.base import AlbedoModel, FaceModel

__all__ = ["AlbedoModel", "FaceModel"]
