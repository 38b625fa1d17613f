"""Writes the current goal sentence onto a camera image, so recorded episodes show what the arm was told."""

from __future__ import annotations

import numpy as np
from PIL import Image, ImageDraw, ImageFont

BAND = 22


def caption(image: np.ndarray, text: str) -> np.ndarray:
    """``image`` (H, W, 3) uint8 with a dark band at the top carrying ``text``."""
    picture = Image.fromarray(image)
    draw = ImageDraw.Draw(picture)
    draw.rectangle((0, 0, picture.width, BAND), fill=(20, 20, 20))
    draw.text((6, 5), text, fill=(255, 255, 255), font=ImageFont.load_default())
    return np.asarray(picture)
