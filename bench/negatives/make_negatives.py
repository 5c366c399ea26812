"""Writes the carcass-free photographs that scikit-image ships to bench/negatives/.

Why: a model trained on renders of carcass piles must not call faces, cats, coffee cups or
walls carcasses (issue 38). These photographs come with scikit-image itself (no download),
so the negative check runs on a fresh clone: the PNGs are committed, and this script says
where they came from. Licences, from skimage.data's docstrings: astronaut, rocket (NASA,
public domain); coffee, chelsea (CC0); camera, coins, clock, brick, grass, gravel (public
domain or CC0, see the docstrings of skimage.data).

Run from the repository root, in a venv with the pinned scikit-image:
    python3 -m venv .venv && .venv/bin/pip install scikit-image==0.25.2
    .venv/bin/python bench/negatives/make_negatives.py
"""
import pathlib

import numpy as np
import skimage
import skimage.data
from PIL import Image

# Ordinary photographs first, then textures a line camera may see (brick, gravel, grass).
NAMES = ["astronaut", "coffee", "chelsea", "rocket", "camera", "coins", "clock", "brick", "gravel", "grass"]


def main() -> None:
    out = pathlib.Path(__file__).resolve().parent
    for name in NAMES:
        image = getattr(skimage.data, name)()
        if image.ndim == 2:  # grayscale photographs are written as RGB, as a camera would
            image = np.stack([image] * 3, axis=-1)
        Image.fromarray(image.astype(np.uint8)).save(out / f"{name}.png", optimize=False)
        print(f"{name}.png {image.shape[1]}x{image.shape[0]}")
    print(f"scikit-image {skimage.__version__}")


if __name__ == "__main__":
    main()
