"""L_lan, the landmark loss, and the coefficient priors used with it in Stage 1.

Paper (Sec. 3.1, after Dib et al. 2021): ``L_lan = 1/|q_in| * ||q_out - q_in||_2``, read here as the
mean over landmarks of the 2D Euclidean distance between the projected model points q_out and the
detected points q_in (the authors' code squares the distances; ``squared=True`` gives that form).
Distances are divided by ``scale`` (pixels), so the loss and its weights do not depend on the image
resolution; Stage 1 uses the face size (see :class:`deface.fit.stage1.Stage1Config.normalise_by`).
"""

from __future__ import annotations

import torch


def landmark_distances(projected: torch.Tensor, detected: torch.Tensor, eps: float = 1e-6) -> torch.Tensor:
    """Euclidean distances [..., N] of projected [..., N, 2] to detected [..., N, 2] (pixels).

    ``eps`` keeps the gradient finite at a zero distance (sqrt(d² + eps²) - eps: exactly 0 at 0).
    """
    if projected.shape != detected.shape or projected.shape[-1] != 2:
        raise ValueError(
            f"landmarks must both be [..., N, 2], got {tuple(projected.shape)} and {tuple(detected.shape)}"
        )
    squared = ((projected - detected) ** 2).sum(-1)
    return torch.sqrt(squared + eps * eps) - eps


def landmark_loss(
    projected: torch.Tensor,
    detected: torch.Tensor,
    scale: float | torch.Tensor,
    weights: torch.Tensor | None = None,
    squared: bool = False,
) -> torch.Tensor:
    """L_lan: weighted mean over points (and over any leading frame dims) of distance / scale.

    projected, detected: [..., N, 2] pixels; scale: pixels (a float or [...] per frame);
    weights: [N] or [..., N] non-negative (None: all 1). squared: mean of (distance / scale)².
    """
    distance = landmark_distances(projected, detected)  # [..., N]
    scale_t = torch.as_tensor(scale, dtype=distance.dtype, device=distance.device)
    if scale_t.ndim:
        scale_t = scale_t[..., None]  # per-frame scale [...] -> [..., 1]
    normalised = distance / scale_t
    if squared:
        normalised = normalised**2
    if weights is None:
        return normalised.mean()
    weights = torch.as_tensor(weights, dtype=distance.dtype, device=distance.device).expand_as(normalised)
    return (normalised * weights).sum() / weights.sum().clamp_min(1e-12)


def identity_prior(identity: torch.Tensor) -> torch.Tensor:
    """mean(alpha²) for N(0, 1) identity coefficients [..., Ki]."""
    return (identity**2).mean()


def blendshape_prior(expression: torch.Tensor) -> torch.Tensor:
    """mean(beta) for blendshape weights in [0, 1] [..., Ke] (an L1 prior: sparse, favours rest pose)."""
    return expression.abs().mean()


def pca_expression_prior(expression: torch.Tensor) -> torch.Tensor:
    """mean(beta²) for N(0, 1) PCA expression coefficients [..., Ke]."""
    return (expression**2).mean()
