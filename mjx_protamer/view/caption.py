"""Caption text drawn onto a rendered frame (Pillow), so a video says what is happening in it."""

from __future__ import annotations

import numpy as np
from PIL import Image, ImageDraw, ImageFont

_FONTS: dict[int, ImageFont.ImageFont] = {}


def _font(size: int):
    if size not in _FONTS:
        _FONTS[size] = ImageFont.load_default(size=size)
    return _FONTS[size]


def draw_caption(frame: np.ndarray, lines: list[str], size: int = 15) -> np.ndarray:
    """The frame with `lines` on a dark band along its bottom edge (same shape, uint8 RGB)."""
    if not lines:
        return frame
    img = Image.fromarray(frame)
    draw = ImageDraw.Draw(img, "RGBA")
    pad, step = 6, size + 4
    top = img.height - pad - step * len(lines)
    draw.rectangle((0, top - pad, img.width, img.height), fill=(0, 0, 0, 150))
    for i, text in enumerate(lines):
        draw.text((pad, top + i * step), text, fill=(255, 255, 255, 255), font=_font(size))
    return np.asarray(img)
