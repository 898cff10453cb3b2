"""Where the fit's hand finder fires (deface/landmarks/hands.py, deface/priors/occluders.py), and what it costs.

For each image: the face's landmarks, MediaPipe's hands at the default threshold, and which of them reach in over
the face (their wrist beyond the face's outline by ``HandConfig.wrist_beyond``), with the time of the hand search.

    DEFACE_MODELS=../shared/models .venv/bin/python benchmarks/hands_over_faces.py IMAGE [IMAGE ...]

The fit runs the same search on its working crop, once per frame.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from deface.io.images import load_image
from deface.landmarks.detect import detect_landmarks
from deface.landmarks.hands import detect_hands
from deface.priors.occluders import HandConfig, reaches_in


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("images", nargs="+")
    images = parser.parse_args().images
    config, seconds, fired = HandConfig(), [], []
    for path in images:
        image = load_image(path)
        try:
            face = detect_landmarks(image).points[:, :2]
        except ValueError:
            print(f"{path}: no face")
            continue
        start = time.perf_counter()
        hands = detect_hands(image, min_confidence=config.min_confidence)
        seconds.append(time.perf_counter() - start)
        over = [hand for hand in hands if reaches_in(hand, face, config.wrist_beyond)]
        if hands:
            print(f"{path}: {len(hands)} hand(s) found, {len(over)} over the face")
        fired += [path] if over else []
    print(f"{len(seconds)} images with a face; a hand over the face in {len(fired)}: {', '.join(fired) or '-'}")
    print(f"hand search: first {seconds[0]:.2f} s (loads the models), then median {np.median(seconds[1:]):.3f} s")


if __name__ == "__main__":
    main()
