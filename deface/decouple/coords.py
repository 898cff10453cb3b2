"""Pixel coordinates fed to the fields f and g.

Two conventions, both mapping a pixel to (x, y, t):
- ``"paper"`` (default): pixel centres, x = 2 (j + 0.5) / W - 1 and y = 2 (i + 0.5) / H - 1, so both lie in
  [-1, 1] whatever the aspect ratio (Sec. 3.2: "(x, y) are normalized into [-1, 1]").
- ``"code"``: the authors' grid, x = 2 j / H - 1 and y = 2 i / H - 1 (both divided by the height, then mapped
  to [-1, 1]); it keeps the aspect ratio, so x exceeds 1 on images wider than tall.
t = i / k for frame i of a k-frame sequence and 0 for one image (``frame_time``).
"""

from __future__ import annotations

import torch

CONVENTIONS = ("paper", "code")


def frame_time(index: int, num_frames: int) -> float:
    """t of frame ``index`` of ``num_frames`` (0 for a single image), in [0, 1)."""
    if num_frames < 1 or not 0 <= index < num_frames:
        raise ValueError(f"frame index {index} out of range for {num_frames} frames")
    return 0.0 if num_frames == 1 else index / num_frames


def pixel_coordinates(height: int, width: int, t: float = 0.0, convention: str = "paper") -> torch.Tensor:
    """Coordinate image [H, W, 3] holding (x, y, t) per pixel; see the module docstring for conventions."""
    if height < 1 or width < 1:
        raise ValueError(f"image size must be positive, got {height}x{width}")
    if not 0.0 <= t <= 1.0:
        raise ValueError(f"t must lie in [0, 1], got {t}")
    if convention == "paper":
        xs = (torch.arange(width, dtype=torch.float32) + 0.5) * (2.0 / width) - 1.0  # [W]
        ys = (torch.arange(height, dtype=torch.float32) + 0.5) * (2.0 / height) - 1.0  # [H]
    elif convention == "code":
        xs = torch.arange(width, dtype=torch.float32) * (2.0 / height) - 1.0
        ys = torch.arange(height, dtype=torch.float32) * (2.0 / height) - 1.0
    else:
        raise ValueError(f"unknown coordinate convention {convention!r}; choose one of {CONVENTIONS}")
    grid_y, grid_x = torch.meshgrid(ys, xs, indexing="ij")  # [H, W] each
    grid_t = torch.full_like(grid_x, float(t))
    return torch.stack([grid_x, grid_y, grid_t], dim=-1)


def video_coordinates(num_frames: int, height: int, width: int, convention: str = "paper") -> torch.Tensor:
    """Coordinates [T, H, W, 3] of every frame of a clip (t = i / T)."""
    return torch.stack(
        [pixel_coordinates(height, width, frame_time(i, num_frames), convention) for i in range(num_frames)]
    )
