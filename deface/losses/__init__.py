"""Losses: pure functions of tensors (landmarks, photometric, segmentation distillation, area, binary)."""
