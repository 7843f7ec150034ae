"""Pictures of detected landmarks over the photograph they were detected in.

This module imports :mod:`albedo_model.io.atomic`.
"""

from __future__ import annotations

import io
import os

import numpy as np

from albedo_model.io.atomic import atomic_path

__all__ = ["landmarks_png"]


def landmarks_png(image: np.ndarray, points: dict[str, tuple[float, float]], path, *,
                  mesh: np.ndarray | None = None, labels: bool = True,
                  title: str = "", box=None) -> None:
    """Write a PNG of ``points`` (name -> (x, y) pixels) over ``image``.

    Parameters
    ----------
    image : (H, W, 3) array
        The photograph (uint8 or floats in [0, 1]).
    points : mapping name -> (x, y)
        Landmarks to draw: subject's left in blue, right in red, centre in yellow.
    path : path-like
        The PNG to write (atomically).
    mesh : (468, 3) array, optional
        The whole detected mesh, drawn as small grey dots.
    labels : bool
        Write each landmark's name beside it.
    title : str
        Shown above the picture.
    box : (x0, y0, x1, y1), optional
        Show only this face box, enlarged to 1.8 times its size (small faces in a
        large photograph stay readable).
    """
    from matplotlib.figure import Figure

    img = np.asarray(image)
    full_h, full_w = img.shape[:2]
    x0, y0, x1, y1 = 0.0, 0.0, float(full_w), float(full_h)
    if box is not None:
        cx, cy = 0.5 * (box[0] + box[2]), 0.5 * (box[1] + box[3])
        half = 0.9 * max(box[2] - box[0], box[3] - box[1])
        x0, x1 = max(0.0, cx - half), min(float(full_w), cx + half)
        y0, y1 = max(0.0, cy - half), min(float(full_h), cy + half)
    h, w = y1 - y0, x1 - x0
    scale = max(1.0, 6.0 * 96 / max(h, w))
    fig = Figure(figsize=(w / 96 * scale, h / 96 * scale + (0.3 if title else 0.0)), dpi=96)
    ax = fig.add_axes((0.0, 0.0, 1.0, h / (h + (28.8 if title else 0.0))))
    ax.imshow(img)
    ax.set_axis_off()
    if mesh is not None:
        ax.plot(mesh[:, 0], mesh[:, 1], ".", ms=1.0, color="0.8")
    for name, (x, y) in points.items():
        side = name.split(".")[0]
        colour = {"left": "#3070ff", "right": "#ff3030"}.get(side, "#ffd000")
        ax.plot([x], [y], "+", ms=8, mew=1.5, color=colour)
        if labels:
            ax.text(x + 2, y - 2, name.split(".", 1)[-1] if side != "center" else name[7:],
                    fontsize=5, color=colour)
    ax.set_xlim(x0 - 0.5, x1 - 0.5)
    ax.set_ylim(y1 - 0.5, y0 - 0.5)
    if title:
        fig.suptitle(title, fontsize=8, y=0.995)
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    with atomic_path(os.fspath(path)) as tmp:
        with open(tmp, "wb") as f:
            f.write(buf.getvalue())
