"""Where the fit's working frames lie in the input's frames: the face at its own resolution (issue 39).

The landmarks are found on the whole input frame (W0 x H0 pixels, as decoded). The frame is then resized by
the working scale s to the *scene* (the whole frame at the working scale, about s W0 x s H0 pixels) and the
working frame is a window of the scene: a square around the face (:func:`choose_framing`). Every fitted
quantity refers back to the input through :class:`Framing`:

- a working position p is the input position ``origin + p / factors`` (``factors``: the resize's working
  pixels per input pixel along x and y; they differ from s only by the rounding of the scene's size);
- the camera keeps the photo's principal point, the input's centre: in working pixels it is
  :attr:`Framing.principal_point`, off the crop's centre when the face is off the photo's; the input's
  camera is :meth:`Framing.input_camera` (focal / s, principal point at the input's centre);
- the composite (``render.png``) is the scene with the working frame's composite pasted at
  :attr:`Framing.scene_offset` (whole scene pixels, so nothing is resampled).

The crop (``FitConfig.crop``): a square of ``margin`` times the larger side of the landmarks' box (a clip: the
box of every frame's landmarks, one crop for the whole clip), centred on the box, moved inside the frame, and
cut to the frame where it is larger. MediaPipe's points run from the chin to the top of the forehead and from
temple to temple, so a margin of 2 leaves half the box's height of hair above the forehead and of neck below
the chin, and about half of it beside each cheek (ears, background): the context the face-region classifier
and the fit use, about the framing of the face datasets the method was trained on (CelebAMask-HQ, FFHQ).
The scene's illuminant still reads the whole scene (deface/priors/illuminant.py).

The working size: the scale is the largest that keeps the crop's longer side within ``resolution`` (the cap)
and never above 1: a face gets every pixel the photo has, up to the cap, and is never upsampled.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from deface.io.images import resize_max
from deface.render.camera import Camera


@dataclass(frozen=True)
class Framing:
    """The working frames as a window of the input frames resized (see the module doc)."""

    input_size: tuple[int, int]  # (W0, H0) pixels of the input frames (as decoded)
    size: tuple[int, int]  # (W, H) pixels of the working frames
    factors: tuple[float, float]  # working pixels per input pixel along x and y (the resize's)
    origin: tuple[float, float]  # input position (x, y) of the working frame's corner (0, 0)

    @classmethod
    def whole(cls, size: tuple[int, int], scale: float) -> Framing:
        """Frames of ``size`` that are the whole input resized by ``scale`` (no crop)."""
        return cls((round(size[0] / scale), round(size[1] / scale)), tuple(size), (scale, scale), (0.0, 0.0))

    @property
    def scale(self) -> float:
        """Working pixels per input pixel along the input's longer side (the focal length's factor)."""
        return self.factors[0] if self.input_size[0] >= self.input_size[1] else self.factors[1]

    @property
    def scene_size(self) -> tuple[int, int]:
        """(W, H) of the scene: the whole input frame at the working scale."""
        return (max(1, round(self.input_size[0] * self.factors[0])),
                max(1, round(self.input_size[1] * self.factors[1])))

    @property
    def scene_offset(self) -> tuple[int, int]:
        """(x, y) whole pixels of the working frame's corner in the scene."""
        return round(self.origin[0] * self.factors[0]), round(self.origin[1] * self.factors[1])

    @property
    def is_whole(self) -> bool:
        """Whether the working frames are the whole scene (no crop: the face fills the photo, or crop is off)."""
        return self.scene_offset == (0, 0) and tuple(self.size) == self.scene_size

    def scene_image(self, image: np.ndarray) -> np.ndarray:
        """An input-sized image [H0, W0, C] resized to the scene [Hs, Ws, C]."""
        return resize_max(image, max(self.scene_size))[0]

    def window(self, scene: np.ndarray) -> np.ndarray:
        """The working frame [H, W, ...] cut from a scene-sized image [Hs, Ws, ...]."""
        (left, top), (width, height) = self.scene_offset, self.size
        return np.ascontiguousarray(scene[top:top + height, left:left + width])

    @property
    def principal_point(self) -> tuple[float, float]:
        """(x, y) working pixels of the input's centre, where the photo's optical axis meets it."""
        return tuple(float(v) for v in self.from_input(np.array([self.input_size[0] / 2, self.input_size[1] / 2])))

    @property
    def box(self) -> tuple[float, float, float, float]:
        """The working frame in input pixels: left, top, right, bottom."""
        right, bottom = self.to_input(np.array(self.size, dtype=np.float64))
        return self.origin[0], self.origin[1], float(right), float(bottom)

    def to_input(self, points: np.ndarray) -> np.ndarray:
        """Working positions [..., 2] -> input positions [..., 2]."""
        return np.asarray(self.origin) + np.asarray(points, dtype=np.float64) / np.asarray(self.factors)

    def from_input(self, points: np.ndarray) -> np.ndarray:
        """Input positions [..., 2] -> working positions [..., 2]."""
        return (np.asarray(points, dtype=np.float64) - np.asarray(self.origin)) * np.asarray(self.factors)

    def input_camera(self, camera: Camera) -> Camera:
        """A working frame's camera as the whole input frame's (focal / scale, principal point at the centre)."""
        width, height = self.input_size
        return Camera(camera.focal / self.scale, camera.rotation, camera.translation, width, height)

    def scene_camera(self, camera: Camera) -> Camera:
        """A working frame's camera as the scene's (the whole frame at the working scale, centred)."""
        width, height = self.scene_size
        return Camera(camera.focal, camera.rotation, camera.translation, width, height)

    def record(self) -> dict:
        """What params.json says of the crop (input pixels) and the working frames."""
        return {"input_size": list(self.input_size), "box": [round(v, 3) for v in self.box],
                "origin": list(self.origin), "size": list(self.size), "scale": self.scale,
                "factors": list(self.factors),
                "scene_size": list(self.scene_size), "scene_offset": list(self.scene_offset),
                "principal_point": [round(v, 4) for v in self.principal_point]}

    @classmethod
    def from_record(cls, record: dict) -> Framing:
        """The framing :meth:`record` wrote."""
        origin = record.get("origin", record["box"][:2])  # the box's corner, rounded, before "origin" was kept
        return cls(tuple(record["input_size"]), tuple(record["size"]), tuple(record["factors"]), tuple(origin))


def face_box(points: list[np.ndarray], input_size: tuple[int, int]) -> tuple[float, float, float, float]:
    """Left, top, right, bottom of the landmarks ``points`` (per frame [P, 2], input pixels) of every frame,
    within the frame."""
    stacked = np.concatenate([np.asarray(p, dtype=np.float64) for p in points])
    low = np.clip(stacked.min(0), 0, input_size)
    high = np.clip(stacked.max(0), 0, input_size)
    return float(low[0]), float(low[1]), float(high[0]), float(high[1])


def choose_framing(input_size: tuple[int, int], box: tuple[float, float, float, float] | None, resolution: int,
                   margin: float) -> Framing:
    """The framing of a face whose landmarks span ``box`` (input pixels; None: no crop, the whole frame) in
    frames of ``input_size``, at most ``resolution`` working pixels on the longer side (module doc)."""
    extent = _crop_extent(input_size, box, margin)  # (left, top, width, height) input pixels
    longest = max(input_size)
    scale = min(1.0, resolution / max(extent[2], extent[3]))
    scene_longest = max(1, round(longest * scale))
    scale = scene_longest / longest  # resize_max's factor for that side (deface/io/images.py)
    scene = (max(1, round(input_size[0] * scale)), max(1, round(input_size[1] * scale)))
    factors = (scene[0] / input_size[0], scene[1] / input_size[1])
    start, size = [], []
    for axis in (0, 1):
        low, length = extent[axis], extent[axis + 2]
        first = min(max(0, round(low * factors[axis])), scene[axis] - 1)
        count = max(1, min(round(length * factors[axis]), scene[axis] - first))
        if length >= input_size[axis]:
            first, count = 0, scene[axis]
        start.append(first)
        size.append(count)
    return Framing(tuple(input_size), (size[0], size[1]), factors,
                   (start[0] / factors[0], start[1] / factors[1]))


def _crop_extent(input_size: tuple[int, int], box, margin: float) -> tuple[float, float, float, float]:
    """(left, top, width, height) in input pixels of the square crop (cut to the frame)."""
    width, height = input_size
    if box is None:
        return 0.0, 0.0, float(width), float(height)
    left, top, right, bottom = box
    side = margin * max(right - left, bottom - top, 1.0)
    out = []
    for centre, length in (((left + right) / 2, width), ((top + bottom) / 2, height)):
        if side >= length:
            out.append((0.0, float(length)))
        else:
            out.append((min(max(0.0, centre - side / 2), length - side), side))
    return out[0][0], out[1][0], out[0][1], out[1][1]


def decode_side(box: tuple[float, float, float, float], decoded_size: tuple[int, int], file_size: tuple[int, int],
                resolution: int, margin: float, max_pixels: int) -> int:
    """The longer side to decode a photo of ``file_size`` at so that its face's crop (landmarks ``box`` found in
    the photo decoded at ``decoded_size``) gets up to ``resolution`` working pixels: never more than the file has
    nor than ``max_pixels`` in all, never less than ``decoded_size``. A small face in a large photo (a half-body
    shot, a group) otherwise lost the pixels the fit's cap would give it to the decoder's cap."""
    longest = max(decoded_size)
    crop = max(_crop_extent(decoded_size, box, margin)[2:])
    wanted = longest * resolution / max(crop, 1.0)
    budget = max(file_size) * math.sqrt(max_pixels / max(file_size[0] * file_size[1], 1))
    return int(max(longest, min(wanted, budget, max(file_size))))


def texture_size_for(texels_per_side: float, limits: tuple[int, int]) -> int:
    """The UV maps' side for a face whose pixels support ``texels_per_side`` (one pixel per texel): the power
    of two nearest it (in log scale), within ``limits`` (smallest, largest)."""
    low, high = limits
    if not math.isfinite(texels_per_side) or texels_per_side <= 0:
        return low
    nearest = 2 ** round(math.log2(texels_per_side))
    return int(min(max(nearest, low), high))
