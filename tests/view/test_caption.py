"""Captions on rendered frames: a long list of touched regions wraps inside the frame instead of running off it."""

import numpy as np
from PIL import Image, ImageDraw

from mjx_protamer.view.caption import _font, _wrap, draw_caption

REGIONS = ("regions touched (8): hip, lower_body, upper_body, head, left_upper_arm, right_upper_arm, "
           "left_lower_arm, right_lower_arm")


def _band_rows(frame: np.ndarray) -> int:
    """Rows darkened by the caption band (the frame is plain white)."""
    return int(np.sum(frame[:, 0, 0] < 200))


def test_a_long_line_wraps_into_the_frame_and_keeps_every_word():
    for width in (240, 480):
        blank = np.full((width, width, 3), 255, np.uint8)
        one = draw_caption(blank, ["step 10"])
        both = draw_caption(blank, ["step 10", REGIONS])
        assert _band_rows(both) >= 2 * _band_rows(one)  # the regions took more than one line
        draw = ImageDraw.Draw(Image.fromarray(blank))
        font = _font(max(8, min(15, width // 30)))
        parts = _wrap(draw, REGIONS, font, width - 12)
        assert len(parts) >= 2 and " ".join(parts) == REGIONS
        assert all(draw.textlength(p, font=font) <= width - 12 for p in parts)


def test_a_short_caption_is_one_line_and_the_frame_keeps_its_shape():
    frame = np.full((120, 160, 3), 255, np.uint8)
    out = draw_caption(frame, ["t=1.00 s"])
    assert out.shape == frame.shape and out.dtype == np.uint8
    assert draw_caption(frame, []) is frame
