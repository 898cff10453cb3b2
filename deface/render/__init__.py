"""Renderer: Embree ray casting, SH lighting with ray-traced self-shadowing, differentiable shading."""

from deface.render.camera import Camera
from deface.render.mesh import Mesh, Textures
from deface.render.renderer import (
    Fragments,
    RenderConfig,
    Renderer,
    RenderOutput,
    ShadowTransferCache,
    vertex_irradiance,
)
from deface.render.sh import cosine_lobe_coefficients, sh_basis
from deface.render.shadow import ShadowTransfer

__all__ = [
    "Camera", "Fragments", "Mesh", "RenderConfig", "RenderOutput", "Renderer", "ShadowTransfer",
    "ShadowTransferCache", "Textures", "cosine_lobe_coefficients", "sh_basis", "vertex_irradiance",
]
