"""Human prior HP (Sec. 3.3): renders under each kept light should look like *someone* to FaceNet.

HP = mean over kept lights k of (1 - max_c softmax(FaceNet(x_k))_c)^2   (``form="code"``, the authors' code)
HP = sum over kept lights k of |1 - max_c softmax(FaceNet(x_k))_c|       (``form="paper"``, Sec. 3.3)

x_k is what FaceNet was trained on (``input_mode="facenet"``, default): the render I_Rs^k cropped to the face
box (from the render coverage, widened by ``margin``), resized to 160x160 with a differentiable bilinear
resampling, turned from linear RGB into sRGB (gamma 1/2.2, the project's convention) and standardised as
(x * 255 - 127.5) / 128. ``input_mode="authors"`` feeds the raw linear full-frame render, as the authors did.

FaceNet's weights (facenet-pytorch's ``20180402-114759-vggface2.pt``) cannot be fetched at run time; place the
file in the models directory. :func:`load_human_prior` returns ``(None, reason)`` when it is absent.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

from deface.paths import ModelFileError, find_model_file, models_dir_candidates
from deface.priors.facenet import InceptionResnetV1

FACENET_FILE = "20180402-114759-vggface2.pt"
FACENET_RELATIVE = ("facenet/" + FACENET_FILE, FACENET_FILE)  # looked up in this order
FACENET_SOURCE = (
    "facenet-pytorch's pretrained VGGFace2 InceptionResnetV1 state dict (107 MB; the URL is in "
    "load_weights() of facenet_pytorch/models/inception_resnet_v1.py, github.com/timesler/facenet-pytorch)"
)
FACENET_SIZE = 160


class MissingWeightsError(ModelFileError):
    """Optional network weights are missing; the message names the file and where to get it."""


@dataclass(frozen=True)
class HumanPriorConfig:
    """How renders are shown to FaceNet and how its confidence becomes a loss."""

    input_mode: str = "facenet"
    """"facenet": face crop, 160x160, sRGB, standardised; "authors": raw linear full frame (as coded)."""
    form: str = "code"
    """"code": mean over lights of (1 - max p)^2; "paper": sum over lights of |1 - max p|."""
    margin: float = 0.2
    """Face box widened by this fraction of its size on each side (FaceNet's crops include some context)."""


def face_box(coverage: torch.Tensor, margin: float = 0.2) -> tuple[int, int, int, int]:
    """Square box (top, left, size_y, size_x) around coverage [H, W] > 0.5, widened by ``margin`` per side."""
    rows = torch.nonzero(coverage.detach() > 0.5)
    if rows.numel() == 0:
        raise ValueError("the render coverage is empty: no face to crop")
    top, left = rows.min(dim=0).values.tolist()
    bottom, right = (rows.max(dim=0).values + 1).tolist()
    side = max(bottom - top, right - left) * (1.0 + 2.0 * margin)
    centre_y, centre_x = (top + bottom) / 2.0, (left + right) / 2.0
    size = int(round(side))
    return int(round(centre_y - side / 2)), int(round(centre_x - side / 2)), size, size


def crop_resize(images: torch.Tensor, box: tuple[int, int, int, int], size: int = FACENET_SIZE):
    """Crop [K, H, W, 3] to box (zero outside the image) and resize to [K, 3, size, size], differentiably."""
    top, left, height, width = box
    image_h, image_w = images.shape[1:3]
    planes = images.permute(0, 3, 1, 2)
    pad = (max(0, -left), max(0, left + width - image_w), max(0, -top), max(0, top + height - image_h))
    planes = F.pad(planes, pad)
    top, left = top + pad[2], left + pad[0]
    crop = planes[:, :, top : top + height, left : left + width]
    return F.interpolate(crop, size=(size, size), mode="bilinear", align_corners=False, antialias=True)


def facenet_input(light_renders: torch.Tensor, coverage: torch.Tensor, margin: float = 0.2) -> torch.Tensor:
    """Linear renders [K, H, W, 3] -> FaceNet input [K, 3, 160, 160] (crop, resize, sRGB, standardise)."""
    crop = crop_resize(light_renders, face_box(coverage, margin))
    srgb = crop.clamp(0.0, 1.0).clamp_min(1e-6) ** (1.0 / 2.2)
    return (srgb * 255.0 - 127.5) / 128.0


class HumanPrior:
    """HP with a FaceNet classifier; call with the kept lights' renders and the render coverage."""

    def __init__(self, weights_path: str | os.PathLike, config: HumanPriorConfig | None = None):
        path = Path(weights_path)
        if not path.is_file():
            raise MissingWeightsError(f"FaceNet weights not found at {path}: get {FACENET_SOURCE}")
        network = InceptionResnetV1()
        state = torch.load(path, map_location="cpu", weights_only=True)
        network.load_state_dict(state, strict=True)
        self._setup(network, config)
        self.weights_path = path

    @classmethod
    def with_network(cls, network: nn.Module, config: HumanPriorConfig | None = None) -> HumanPrior:
        """A prior around any classifier mapping [K, 3, h, w] to logits [K, classes] (tests, other nets)."""
        prior = cls.__new__(cls)
        prior._setup(network, config)
        prior.weights_path = None
        return prior

    def _setup(self, network: nn.Module, config: HumanPriorConfig | None) -> None:
        self.config = config or HumanPriorConfig()
        if self.config.input_mode not in ("facenet", "authors") or self.config.form not in ("code", "paper"):
            raise ValueError(f"bad HumanPriorConfig {self.config}")
        self.network = network.eval()  # BatchNorm running statistics, no dropout
        for parameter in self.network.parameters():
            parameter.requires_grad_(False)

    def network_input(self, light_renders: torch.Tensor, coverage: torch.Tensor) -> torch.Tensor:
        if light_renders.dim() != 4 or light_renders.shape[-1] != 3:
            raise ValueError(f"light_renders must be [K, H, W, 3], got {tuple(light_renders.shape)}")
        if self.config.input_mode == "authors":
            return light_renders.permute(0, 3, 1, 2)
        return facenet_input(light_renders, coverage, self.config.margin)

    def confidence(self, light_renders: torch.Tensor, coverage: torch.Tensor) -> torch.Tensor:
        """max softmax probability [K] of each render."""
        logits = self.network(self.network_input(light_renders, coverage))
        return torch.softmax(logits, dim=-1).max(dim=-1).values

    def __call__(self, light_renders: torch.Tensor, coverage: torch.Tensor) -> torch.Tensor:
        """HP (scalar) of renders [K, H, W, 3] (linear RGB, one per kept light) with coverage [H, W]."""
        confidence = self.confidence(light_renders, coverage)
        if self.config.form == "code":
            return ((1.0 - confidence) ** 2).mean()
        return (1.0 - confidence).abs().sum()


def find_facenet_weights(models_dir: str | os.PathLike | None = None) -> Path | None:
    for relative in FACENET_RELATIVE:
        found = find_model_file(relative, models_dir)
        if found is not None:
            return found
    return None


def load_human_prior(
    models_dir: str | os.PathLike | None = None, config: HumanPriorConfig | None = None
) -> tuple[HumanPrior | None, str]:
    """(HumanPrior, "") when FaceNet's weights are found, else (None, reason) for the run record."""
    path = find_facenet_weights(models_dir)
    if path is None:
        searched = ", ".join(str(d) for d in models_dir_candidates(models_dir))
        return None, (
            f"HP off: {FACENET_FILE} not found (looked for {' or '.join(FACENET_RELATIVE)} in {searched}); "
            f"get {FACENET_SOURCE}"
        )
    return HumanPrior(path, config), ""
