"""What the camera does to the light of a rendered frame: exposure and white balance, blur and
sensor noise, drawn from the frame's random stream. No I/O, no scene content.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


def expose(
    img: NDArray[np.float32], rng: np.random.Generator, grain: NDArray[np.float32]
) -> NDArray[np.uint8]:
    """The camera images of the light ``img`` (C, H, W, 3) float32, changed in place: exposure /
    white balance per camera, horizontal and vertical blur, and noise read from ``grain`` (drawn
    once per renderer, longer than ``img``) at a random offset. Returns (C, 3, H, W) uint8."""
    c = img.shape[0]
    gain = np.exp(rng.normal(0.0, 0.12)) * np.exp(
        rng.normal(0.0, 0.04, size=(c, 1, 1, 1))
    )  # (C,1,1,1)
    gain = gain * np.exp(rng.normal(0.0, 0.03, size=(1, 1, 1, 3)))  # (C, 1, 1, 3)
    img *= gain.astype(np.float32)
    a = np.float32(rng.uniform(0.1, 0.6))
    img[:, :, 1:-1] = (1 - a) * img[:, :, 1:-1] + (a / 2) * (img[:, :, :-2] + img[:, :, 2:])
    b = np.float32(rng.uniform(0.0, 0.4))
    img[:, 1:-1] = (1 - b) * img[:, 1:-1] + (b / 2) * (img[:, :-2] + img[:, 2:])
    n = img.size
    off = int(rng.integers(0, grain.size - n))
    img += np.float32(rng.uniform(1.5, 5.0)) * grain[off : off + n].reshape(img.shape)
    out = np.clip(img, 0.0, 255.0).astype(np.uint8)  # (C, H, W, 3)
    return np.ascontiguousarray(out.transpose(0, 3, 1, 2))  # (C, 3, H, W)
