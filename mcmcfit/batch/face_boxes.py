"""The default face box for images without landmarks (LFW's 250x250 crops).

LFW's images were made by running the Viola-Jones face detector on the
original photograph, enlarging the detected square by a factor of 2.2 about
its centre and scaling that region to 250x250 pixels. The detected face is
therefore the central square of side 250 / 2.2 ~ 113.6 px:
``(68.2, 68.2, 181.8, 181.8)`` in a 250x250 image, i.e. the fractions
``(0.2727, 0.2727, 0.7273, 0.7273)`` of the image. For other sizes the box
scales with the image (the same fractions). The face-box likelihood
(:class:`mcmcfit.targets.landmarks.FaceBoxTarget`) treats the box as a rough
measurement (10 % scale and centre spread), so the detector's jitter is
absorbed by the sampler.

This module imports only the standard library.
"""

from __future__ import annotations

__all__ = ["LFW_ENLARGEMENT", "LFW_FACE_BOX_FRACTIONS", "lfw_face_box", "parse_face_box"]

#: LFW enlarged the detected face square by this factor before cropping.
LFW_ENLARGEMENT = 2.2

_HALF = 0.5 / LFW_ENLARGEMENT

#: (x0, y0, x1, y1) of the default box as fractions of the image width / height.
LFW_FACE_BOX_FRACTIONS = (0.5 - _HALF, 0.5 - _HALF, 0.5 + _HALF, 0.5 + _HALF)


def lfw_face_box(width: int, height: int) -> tuple[float, float, float, float]:
    """Return the default face box ``(x0, y0, x1, y1)`` in pixels for an image of this size.

    Parameters
    ----------
    width, height : int
        Image size in pixels (250x250 for LFW).

    Returns
    -------
    tuple of 4 float
        Pixel coordinates (x right, y down); ``(68.18, 68.18, 181.82, 181.82)`` for 250x250.
    """
    if width < 1 or height < 1:
        raise ValueError(f"image size must be positive, got {width}x{height}")
    fx0, fy0, fx1, fy1 = LFW_FACE_BOX_FRACTIONS
    return (fx0 * width, fy0 * height, fx1 * width, fy1 * height)


def parse_face_box(text: str) -> tuple[float, float, float, float]:
    """Parse ``"x0,y0,x1,y1"`` (pixels) into a box with x1 > x0 and y1 > y0.

    Raises
    ------
    ValueError
        Not four numbers, or an empty box.
    """
    try:
        values = tuple(float(v) for v in text.replace(" ", "").split(","))
    except ValueError:
        raise ValueError(f"face box must be x0,y0,x1,y1 in pixels, got {text!r}") from None
    if len(values) != 4 or not (values[2] > values[0] and values[3] > values[1]):
        raise ValueError(f"face box must be x0,y0,x1,y1 with x1 > x0 and y1 > y0, got {text!r}")
    return values  # type: ignore[return-value]
