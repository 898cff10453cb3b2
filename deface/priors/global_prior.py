"""Global prior GP (Sec. 3.3): keep the overall hue of the diffuse map near the initial one's palette.

C = k = 16 K-means centres (the paper's "4 x 4 colour matrix") of the initial diffuse UV map T_D^0
(sklearn KMeans, init='random', random_state=seed, as the authors).
GP = sum_t w(t) min_c d(T_D(t), c) / sum_t w(t) over texels t with mask weights w, where
d = ||.||^2 (``squared=True``, the code) or ||.||_2 (``squared=False``, the paper). The paper divides by
|I_in|; dividing by the masked texel count makes the value independent of the resolution (a constant
factor otherwise).
"""

from __future__ import annotations

import numpy as np
import torch


def kmeans_palette(
    diffuse0: torch.Tensor | np.ndarray,
    mask: torch.Tensor | np.ndarray | None = None,
    k: int = 16,
    seed: int = 0,
    max_samples: int = 20000,
    n_init: int = 10,
) -> torch.Tensor:
    """K-means centres [k, 3] of the texels of diffuse0 [Ht, Wt, 3] where mask [Ht, Wt] > 0.5.

    At most ``max_samples`` texels (drawn with ``seed``) are clustered: K-means on a random subsample finds
    the same palette within noise. ``n_init=10`` restarts was sklearn's default when the authors ran it.
    """
    from sklearn.cluster import KMeans

    if isinstance(diffuse0, torch.Tensor):
        diffuse0 = diffuse0.detach().cpu().numpy()
    colours = np.asarray(diffuse0, np.float64)
    if colours.ndim != 3 or colours.shape[-1] != 3:
        raise ValueError(f"diffuse0 must be [Ht, Wt, 3], got {colours.shape}")
    colours = colours.reshape(-1, 3)
    if mask is not None:
        keep = np.asarray(mask.detach().cpu() if isinstance(mask, torch.Tensor) else mask).reshape(-1) > 0.5
        if keep.shape[0] != colours.shape[0]:
            raise ValueError("mask must have the texture's height and width")
        colours = colours[keep]
    if colours.shape[0] < k:
        raise ValueError(f"need at least k={k} texels inside the mask, got {colours.shape[0]}")
    rng = np.random.default_rng(seed)
    if colours.shape[0] > max_samples:
        colours = colours[rng.choice(colours.shape[0], max_samples, replace=False)]
    kmeans = KMeans(n_clusters=k, init="random", n_init=n_init, random_state=seed).fit(colours)
    return torch.as_tensor(kmeans.cluster_centers_, dtype=torch.float32)


def global_prior(
    diffuse: torch.Tensor, centres: torch.Tensor, mask: torch.Tensor | None = None, squared: bool = True
) -> torch.Tensor:
    """GP (scalar): weighted mean over texels of min_c ||T_D - c||^2 (or ||.|| when ``squared=False``)."""
    if diffuse.dim() != 3 or diffuse.shape[-1] != centres.shape[-1]:
        raise ValueError(f"diffuse must be [Ht, Wt, C] matching centres {tuple(centres.shape)}")
    centres = centres.to(diffuse)
    # ||x - c||^2 = ||x||^2 - 2 x.c + ||c||^2: a matmul instead of an [Ht, Wt, k, C] difference tensor
    distances = (diffuse**2).sum(-1, keepdim=True) - 2.0 * diffuse @ centres.T + (centres**2).sum(-1)
    nearest = distances.min(dim=-1).values.clamp_min(0.0)  # [Ht, Wt]
    if not squared:
        nearest = torch.sqrt(nearest + 1e-12)
    if mask is None:
        return nearest.mean()
    if mask.shape != nearest.shape:
        raise ValueError(f"mask {tuple(mask.shape)} must be [Ht, Wt] = {tuple(nearest.shape)}")
    weights = mask.to(nearest)
    return (weights * nearest).sum() / weights.sum().clamp_min(1e-8)
