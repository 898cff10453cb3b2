"""Loading inputs: images (EXIF orientation, sRGB <-> linear), folders, video frames."""

from deface.io.images import InputError, linear_to_srgb, load_image, one_line, resize_max, srgb_to_linear
from deface.io.inputs import InputItem, list_inputs
from deface.io.video import read_spread_frames, read_video_frames

__all__ = [
    "InputError",
    "InputItem",
    "linear_to_srgb",
    "list_inputs",
    "load_image",
    "one_line",
    "read_spread_frames",
    "read_video_frames",
    "resize_max",
    "srgb_to_linear",
]
