"""BiSeNet face parser (zllrunning/face-parsing.PyTorch), written in plain torch with upstream's module names.

ResNet-18 context path + feature fusion, 19 CelebAMask-HQ classes; the checkpoint ``79999_iter.pth`` loads
with strict key matching. Face = classes {1 skin, 2/3 brows, 4/5 eyes, 10 nose, 11 mouth, 12/13 lips}; not face:
0 background, 6 eyeglasses, 7/8 ears, 9 earring, 14 neck, 15 necklace, 16 cloth, 17 hair, 18 hat.
:class:`BiSeNetFaceParser` crops the image around the landmark box (1.1x wide, 1.25x tall), resizes the crop
to 512^2, normalises it with ImageNet statistics, sums the softmax of the face classes and pastes the result
back into the full frame. The checkpoint cannot be fetched at run time: place it in the models directory.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from deface.paths import find_model_file
from deface.priors.human import MissingWeightsError

PARSER_FILE = "79999_iter.pth"
PARSER_RELATIVE = ("face-parsing/" + PARSER_FILE, PARSER_FILE)
PARSER_SOURCE = (
    "the BiSeNet face-parsing checkpoint 79999_iter.pth of github.com/zllrunning/face-parsing.PyTorch "
    "(link in its README)"
)
CELEBAMASK_CLASSES = ("background", "skin", "l_brow", "r_brow", "l_eye", "r_eye", "eye_g", "l_ear", "r_ear", "ear_r",
                      "nose", "mouth", "u_lip", "l_lip", "neck", "neck_l", "cloth", "hair", "hat")
"""The checkpoint's 19 classes, in its output order (CelebAMask-HQ's labels; eye_g: eyeglasses, ear_r: earring,
neck_l: necklace)."""
FACE_CLASSES = (1, 2, 3, 4, 5, 10, 11, 12, 13)
"""The classes h counts as face: the skin and the face's own features. Eyeglasses, hair, a hat, cloth, ears and
jewellery, which cover the face or lie beside it, are not (the offline classifier's occluder finder looks for the
same, deface/priors/occluders.py)."""
MOUTH_CLASS = 11
"""The mouth's opening (teeth, tongue, between the inner lips), left out of h with
``SkinClassifierConfig.mouth_opening`` (the default; the paper counts it as face)."""
EYE_CLASSES = (4, 5)
"""The eyes' openings (between the lids), left out of h with ``SkinClassifierConfig.eye_opening`` (the default;
the paper counts them as face)."""
IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)


def _conv3x3(in_chan: int, out_chan: int, stride: int = 1) -> nn.Conv2d:
    return nn.Conv2d(in_chan, out_chan, 3, stride=stride, padding=1, bias=False)


class BasicBlock(nn.Module):
    def __init__(self, in_chan: int, out_chan: int, stride: int = 1):
        super().__init__()
        self.conv1 = _conv3x3(in_chan, out_chan, stride)
        self.bn1 = nn.BatchNorm2d(out_chan)
        self.conv2 = _conv3x3(out_chan, out_chan)
        self.bn2 = nn.BatchNorm2d(out_chan)
        self.relu = nn.ReLU(inplace=True)
        self.downsample = None
        if in_chan != out_chan or stride != 1:
            self.downsample = nn.Sequential(
                nn.Conv2d(in_chan, out_chan, 1, stride=stride, bias=False), nn.BatchNorm2d(out_chan)
            )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        residual = self.bn2(self.conv2(F.relu(self.bn1(self.conv1(x)))))
        shortcut = x if self.downsample is None else self.downsample(x)
        return self.relu(shortcut + residual)


def _layer(in_chan: int, out_chan: int, stride: int) -> nn.Sequential:
    return nn.Sequential(BasicBlock(in_chan, out_chan, stride), BasicBlock(out_chan, out_chan, 1))


class Resnet18(nn.Module):
    def __init__(self):
        super().__init__()
        self.conv1 = nn.Conv2d(3, 64, 7, stride=2, padding=3, bias=False)
        self.bn1 = nn.BatchNorm2d(64)
        self.maxpool = nn.MaxPool2d(3, stride=2, padding=1)
        self.layer1 = _layer(64, 64, 1)
        self.layer2 = _layer(64, 128, 2)
        self.layer3 = _layer(128, 256, 2)
        self.layer4 = _layer(256, 512, 2)

    def forward(self, x: torch.Tensor):
        x = self.layer1(self.maxpool(F.relu(self.bn1(self.conv1(x)))))
        feat8 = self.layer2(x)
        feat16 = self.layer3(feat8)
        return feat8, feat16, self.layer4(feat16)


class ConvBNReLU(nn.Module):
    def __init__(self, in_chan: int, out_chan: int, ks: int = 3, stride: int = 1, padding: int = 1):
        super().__init__()
        self.conv = nn.Conv2d(in_chan, out_chan, ks, stride=stride, padding=padding, bias=False)
        self.bn = nn.BatchNorm2d(out_chan)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.relu(self.bn(self.conv(x)))


class BiSeNetOutput(nn.Module):
    def __init__(self, in_chan: int, mid_chan: int, n_classes: int):
        super().__init__()
        self.conv = ConvBNReLU(in_chan, mid_chan)
        self.conv_out = nn.Conv2d(mid_chan, n_classes, 1, bias=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.conv_out(self.conv(x))


class AttentionRefinementModule(nn.Module):
    def __init__(self, in_chan: int, out_chan: int):
        super().__init__()
        self.conv = ConvBNReLU(in_chan, out_chan)
        self.conv_atten = nn.Conv2d(out_chan, out_chan, 1, bias=False)
        self.bn_atten = nn.BatchNorm2d(out_chan)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        feat = self.conv(x)
        attention = torch.sigmoid(self.bn_atten(self.conv_atten(F.adaptive_avg_pool2d(feat, 1))))
        return feat * attention


class ContextPath(nn.Module):
    def __init__(self):
        super().__init__()
        self.resnet = Resnet18()
        self.arm16 = AttentionRefinementModule(256, 128)
        self.arm32 = AttentionRefinementModule(512, 128)
        self.conv_head32 = ConvBNReLU(128, 128)
        self.conv_head16 = ConvBNReLU(128, 128)
        self.conv_avg = ConvBNReLU(512, 128, ks=1, padding=0)

    def forward(self, x: torch.Tensor):
        feat8, feat16, feat32 = self.resnet(x)
        avg = self.conv_avg(F.adaptive_avg_pool2d(feat32, 1))
        feat32_sum = self.arm32(feat32) + F.interpolate(avg, feat32.shape[2:], mode="nearest")
        feat32_up = self.conv_head32(F.interpolate(feat32_sum, feat16.shape[2:], mode="nearest"))
        feat16_sum = self.arm16(feat16) + feat32_up
        feat16_up = self.conv_head16(F.interpolate(feat16_sum, feat8.shape[2:], mode="nearest"))
        return feat8, feat16_up, feat32_up


class FeatureFusionModule(nn.Module):
    def __init__(self, in_chan: int, out_chan: int):
        super().__init__()
        self.convblk = ConvBNReLU(in_chan, out_chan, ks=1, padding=0)
        self.conv1 = nn.Conv2d(out_chan, out_chan // 4, 1, bias=False)
        self.conv2 = nn.Conv2d(out_chan // 4, out_chan, 1, bias=False)

    def forward(self, fsp: torch.Tensor, fcp: torch.Tensor) -> torch.Tensor:
        feat = self.convblk(torch.cat([fsp, fcp], dim=1))
        attention = torch.sigmoid(self.conv2(F.relu(self.conv1(F.adaptive_avg_pool2d(feat, 1)))))
        return feat * attention + feat


class BiSeNet(nn.Module):
    """x [B, 3, H, W] (ImageNet-normalised) -> (logits, logits16, logits32), each [B, n_classes, H, W]."""

    def __init__(self, n_classes: int = 19):
        super().__init__()
        self.cp = ContextPath()
        self.ffm = FeatureFusionModule(256, 256)
        self.conv_out = BiSeNetOutput(256, 256, n_classes)
        self.conv_out16 = BiSeNetOutput(128, 64, n_classes)
        self.conv_out32 = BiSeNetOutput(128, 64, n_classes)

    def forward(self, x: torch.Tensor):
        size = x.shape[2:]
        feat_res8, feat_cp8, feat_cp16 = self.cp(x)
        outputs = (
            self.conv_out(self.ffm(feat_res8, feat_cp8)),
            self.conv_out16(feat_cp8),
            self.conv_out32(feat_cp16),
        )
        return tuple(F.interpolate(o, size, mode="bilinear", align_corners=True) for o in outputs)


def parsing_box(points: np.ndarray, image_shape: tuple[int, int]) -> tuple[int, int, int, int]:
    """(top, left, bottom, right) of the landmark box widened 1.1x horizontally and 1.25x vertically."""
    (x0, y0), (x1, y1) = points.min(axis=0), points.max(axis=0)
    cx, cy, half_w, half_h = (x0 + x1) / 2, (y0 + y1) / 2, 1.1 * (x1 - x0) / 2, 1.25 * (y1 - y0) / 2
    height, width = image_shape
    top, bottom = int(max(0, np.floor(cy - half_h))), int(min(height, np.ceil(cy + half_h)))
    left, right = int(max(0, np.floor(cx - half_w))), int(min(width, np.ceil(cx + half_w)))
    if bottom - top < 2 or right - left < 2:
        raise ValueError("the face box is empty")
    return top, left, bottom, right


class BiSeNetFaceParser:
    """h from BiSeNet: image [H, W, 3] sRGB in [0, 1] -> face probability [H, W] (a FaceRegionClassifier)."""

    def __init__(self, checkpoint: str | os.PathLike, input_size: int = 512, face_classes=FACE_CLASSES):
        path = Path(checkpoint)
        if not path.is_file():
            raise MissingWeightsError(f"face-parsing checkpoint not found at {path}: get {PARSER_SOURCE}")
        self.network = BiSeNet(19)
        self.network.load_state_dict(torch.load(path, map_location="cpu", weights_only=True), strict=True)
        self.network.eval()
        self.input_size = input_size
        self.face_classes = tuple(face_classes)

    @classmethod
    def from_models_dir(cls, models_dir: str | os.PathLike | None = None, face_classes=FACE_CLASSES
                        ) -> BiSeNetFaceParser:
        for relative in PARSER_RELATIVE:
            found = find_model_file(relative, models_dir)
            if found is not None:
                return cls(found, face_classes=face_classes)
        raise MissingWeightsError(f"{PARSER_FILE} not found in the models directory: get {PARSER_SOURCE}")

    @torch.no_grad()
    def __call__(self, image, coverage=None, landmarks=None) -> np.ndarray:
        image = np.asarray(image, dtype=np.float32)
        if image.ndim != 3 or image.shape[-1] != 3:
            raise ValueError(f"image must be [H, W, 3], got {image.shape}")
        if landmarks is not None:
            points = np.asarray(landmarks, dtype=np.float64)[:, :2]
        elif coverage is not None:
            ys, xs = np.nonzero(np.asarray(coverage) > 0.5)
            points = np.stack([xs, ys], axis=1).astype(np.float64)
        else:
            points = np.array([[0.0, 0.0], [image.shape[1] - 1.0, image.shape[0] - 1.0]])
        top, left, bottom, right = parsing_box(points, image.shape[:2])
        crop = torch.from_numpy(np.ascontiguousarray(image[top:bottom, left:right])).permute(2, 0, 1)[None]
        crop = F.interpolate(crop, (self.input_size,) * 2, mode="bilinear", align_corners=False)
        crop = (crop - torch.tensor(IMAGENET_MEAN)[:, None, None]) / torch.tensor(IMAGENET_STD)[:, None, None]
        classes = torch.softmax(self.network(crop)[0], dim=1)  # [1, 19, S, S]
        probabilities = classes[:, list(self.face_classes)].sum(dim=1, keepdim=True)
        size = (bottom - top, right - left)
        pasted = F.interpolate(probabilities, size, mode="bilinear", align_corners=False)
        face = np.zeros(image.shape[:2], dtype=np.float32)
        face[top:bottom, left:right] = pasted[0, 0].numpy()
        return face
