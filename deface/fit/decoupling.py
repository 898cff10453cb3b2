"""The light-decoupling state one fit carries through stages 2 and 3: fields f and g, their pixel
coordinates per frame, the classifier target h, and how M_L, M_o are formed under the config's switches.

Switch semantics (the paper's ablations):
- ``light_masks`` off: no f; every kept light gets mask 1/K (with n = 1: the single light, NextFace).
- ``face_region`` off: no g; M_o = M_R * h when ``restrict_to_face`` (NextFace*), else M_o = M_R.
"""

from __future__ import annotations

import torch

from deface.decouple.ace import ace_select
from deface.decouple.coords import video_coordinates
from deface.decouple.fields import FaceRegionField, LightMaskField
from deface.decouple.fill import fill_from_evidence
from deface.fit.config import DecoupleConfig


class Decoupling(torch.nn.Module):
    """f, g and their inputs for T frames of size H x W."""

    def __init__(self, config: DecoupleConfig, num_lights: int, num_frames: int, size: tuple[int, int],
                 light_groups: tuple[int, ...] | None = None):
        """``light_groups``: per frame, the group whose lights its masks choose among (the ``num_lights`` split into
        equal consecutive groups: several photos, each with its own lights); None: every frame all lights."""
        super().__init__()
        self.light_groups = tuple(light_groups) if light_groups is not None else None
        self.group_size = num_lights // len(set(light_groups)) if light_groups is not None else num_lights
        width, height = size
        self.config = config
        self.light_field = (
            LightMaskField(num_lights, hidden=config.hidden, fourier_frequencies=config.fourier_frequencies,
                           uniform_start=config.uniform_start)
            if config.light_masks
            else None
        )
        self.region_field = FaceRegionField() if config.face_region else None
        self.register_buffer("coords", video_coordinates(num_frames, height, width))  # [T, H, W, 3]
        self._other_sizes: dict[tuple[int, int], torch.Tensor] = {}  # stage 2's half-size level
        self._kept = list(range(num_lights))
        self._evidence: dict[tuple[int, int], torch.Tensor] = {}  # [T, H, W] per size (set_evidence)

    def set_evidence(self, evidence: torch.Tensor) -> None:
        """Stage 2's shading evidence [T, H, W] in [0, 1] (h times deface/priors/shading_evidence.py's weight):
        with ``config.mask_fill``, masks where it is low come from the pixels around (deface/decouple/fill.py)."""
        self._evidence = {tuple(evidence.shape[1:]): evidence.float()}

    @property
    def kept(self) -> list[int]:
        """Light indices in use (all before ACE)."""
        return list(self._kept)

    def light_masks(self, frame: int, coverage: torch.Tensor) -> torch.Tensor:
        """M_L [K_kept, H, W] = M_R * f (renormalised over kept lights), or uniform without f."""
        if self.light_field is None:
            share = self.frame_lights(frame, coverage.dtype)
            return (share / share.sum())[:, None, None] * coverage
        # f only where the face is rendered: M_N = M_R * f is zero elsewhere, and this halves the cost.
        covered = coverage > 0
        masks = coverage.new_zeros((*coverage.shape, len(self._kept)))  # [H, W, K_kept]
        masks = masks.index_put((covered,), self._frame_masks(frame, self._coordinates(frame, covered.shape)[covered]))
        masks = masks.permute(2, 0, 1) * coverage
        if not self._evidence or self.config.mask_fill <= 0 or masks.shape[0] < 2:
            return masks
        evidence = self._evidence_at(frame, tuple(coverage.shape)) * coverage
        side = max(coverage.shape)
        filled = fill_from_evidence(masks, evidence, self.config.mask_fill * side, self.config.mask_fill_near * side)
        return filled * coverage

    def _frame_masks(self, frame: int, coords: torch.Tensor) -> torch.Tensor:
        """f at ``coords`` [N, 3] over the kept lights [N, K_kept]; with light groups, renormalised over the kept
        lights of the frame's group (0 for the others: the softmax over that subset)."""
        masks = self.light_field(coords)
        if self.light_groups is None:
            return masks
        masks = masks * self.frame_lights(frame, masks.dtype)
        return masks / masks.sum(-1, keepdim=True).clamp_min(1e-12)

    def frame_lights(self, frame: int, dtype: torch.dtype = torch.bool) -> torch.Tensor:
        """[K_kept] 1 for the kept lights the frame may use (its group's; all without groups), else 0."""
        if self.light_groups is None:
            return torch.ones(len(self._kept), dtype=dtype)
        group = self.light_groups[frame]
        return torch.tensor([k // self.group_size == group for k in self._kept], dtype=dtype)

    def _evidence_at(self, frame: int, shape: tuple[int, int]) -> torch.Tensor:
        """The evidence [H, W] of ``frame`` at ``shape`` (resampled from the size it was set at)."""
        if shape not in self._evidence:
            source = next(iter(self._evidence.values()))
            self._evidence[shape] = torch.nn.functional.interpolate(
                source[:, None], size=shape, mode="bilinear", align_corners=False)[:, 0].clamp(0.0, 1.0)
        return self._evidence[shape][frame]

    def region_probability(self, frame: int, coverage: torch.Tensor) -> torch.Tensor | None:
        """g [H, W] where the face is rendered (0 elsewhere: M_o = M_R g and L_seg only see it there)."""
        if self.region_field is None:
            return None
        return self.region_field.masked(self._coordinates(frame, coverage.shape), coverage > 0)

    def _coordinates(self, frame: int, shape: torch.Size) -> torch.Tensor:
        """(x, y, t) [H, W, 3] of the frame's pixel centres for an [H, W] frame (the working size or
        stage 2's half size: the same normalised range)."""
        frames, height, width = self.coords.shape[:3]
        if tuple(shape) == (height, width):
            return self.coords[frame]
        if tuple(shape) not in self._other_sizes:
            self._other_sizes[tuple(shape)] = video_coordinates(frames, *shape)
        return self._other_sizes[tuple(shape)][frame]

    def face_region(self, frame: int, coverage: torch.Tensor, classifier: torch.Tensor | None,
                    probability: torch.Tensor | None = None) -> torch.Tensor:
        """M_o [H, W] under the switches (see module doc); ``probability`` reuses an evaluated g."""
        if self.region_field is not None:
            if probability is None:
                probability = self.region_probability(frame, coverage)
            return coverage * probability
        if self.config.restrict_to_face and classifier is not None:
            return coverage * classifier
        return coverage

    def run_ace(self, all_masks: torch.Tensor, coverage: torch.Tensor) -> list[int]:
        """Select kept lights from M_N [T, n, H, W] (all lights) and M_R [T, H, W]; returns kept indices."""
        if self.light_groups is None:
            kept = ace_select(all_masks, coverage, self.config.epsilon, self.config.area_normaliser)
        else:  # each group's lights judged on its own frames: a photo's light is not diluted by the others'
            kept = []
            for group in sorted(set(self.light_groups)):
                frames = [t for t, g in enumerate(self.light_groups) if g == group]
                lights = list(range(group * self.group_size, (group + 1) * self.group_size))
                chosen = ace_select(all_masks[frames][:, lights], coverage[frames], self.config.epsilon,
                                    self.config.area_normaliser)
                kept += [lights[i] for i in chosen]
        self._kept = kept
        if self.light_field is not None:
            self.light_field.keep(kept)
        return kept
