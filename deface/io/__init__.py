"""Loading inputs: images (EXIF orientation, sRGB <-> linear), folders, video frames."""
