"""Caption text drawn onto a rendered frame (Pillow), so a video says what is happening in it."""

from __future__ import annotations

import numpy as np
from PIL import Image, ImageDraw, ImageFont

_FONTS: dict[int, ImageFont.ImageFont] = {}


def _font(size: int):
    if size not in _FONTS:
        _FONTS[size] = ImageFont.load_default(size=size)
    return _FONTS[size]


def _wrap(draw, text: str, font, width: float) -> list[str]:
    """`text` broken at spaces into lines no wider than `width` (a single over-long word stays whole)."""
    out, line = [], ""
    for word in text.split(" "):
        trial = f"{line} {word}" if line else word
        if line and draw.textlength(trial, font=font) > width:
            out.append(line)
            line = word
        else:
            line = trial
    return out + [line]


def draw_caption(frame: np.ndarray, lines: list[str], size: int = 15) -> np.ndarray:
    """The frame with `lines` on a dark band along its bottom edge (same shape, uint8 RGB); a line wider
    than the frame wraps, and a small frame gets a smaller font (a list of 8 touched regions must fit)."""
    if not lines:
        return frame
    img = Image.fromarray(frame)
    draw = ImageDraw.Draw(img, "RGBA")
    size = max(8, min(size, img.width // 30))
    font = _font(size)
    pad, step = 6, size + 4
    lines = [part for text in lines for part in _wrap(draw, text, font, img.width - 2 * pad)]
    top = img.height - pad - step * len(lines)
    draw.rectangle((0, top - pad, img.width, img.height), fill=(0, 0, 0, 150))
    for i, text in enumerate(lines):
        draw.text((pad, top + i * step), text, fill=(255, 255, 255, 255), font=font)
    return np.asarray(img)
