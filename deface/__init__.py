"""deface: shadow-free 3D face textures by learning to decouple the lights (Huang et al., NeurIPS 2024)."""

__version__ = "0.1.0"
