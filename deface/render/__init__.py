"""Renderer: Embree ray casting, SH lighting with ray-traced self-shadowing, differentiable shading."""
