"""Preview pictures of per-vertex albedo maps: rendered views side by side.

Each map is ray cast from the frontal photometric camera of the synthetic
lightstage and from the two profile poses, unlit (the albedo itself),
gamma-encoded with the pure 2.2 power, and laid out in a grid with titles
(matplotlib). Used to look at recovered maps next to the truth (seams show
up as edges that the truth does not have).

This module imports :mod:`albedo_model`, :mod:`pipeline.lightstage.camera_render` and
:mod:`pipeline.synthetic.dome`.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np

from albedo_model.errors import InputError
from albedo_model.io.atomic import atomic_path
from albedo_model.render.raycast import RayCaster
from pipeline.synthetic.dome import build_rig, pose_transform
from pipeline.lightstage.camera_render import render_vertex_values

__all__ = ["render_albedo_views", "write_albedo_preview"]


def render_albedo_views(vertices: np.ndarray, triangles: np.ndarray, colours: np.ndarray, *,
                        poses: Sequence[str] = ("frontal", "left", "right"),
                        resolution: int = 320, scale: float = 1.0) -> list[np.ndarray]:
    """Unlit renderings of per-vertex colours, one (H, W, 3) float image per pose, gamma 2.2.

    Parameters
    ----------
    vertices : (n, 3) float array, template frame, mm
    triangles : (m, 3) int array
    colours : (n, 3) float array, linear
    poses : sequence of {"frontal", "left", "right"}
    resolution : int
    scale : float
        Colours are multiplied by this before encoding (e.g. 2 for dim specular maps).
    """
    c = np.asarray(colours, np.float64)
    if c.shape != (len(vertices), 3):
        raise InputError(f"colours must have shape ({len(vertices)}, 3), got {c.shape}")
    cam = build_rig(resolution=resolution, extra_resolution=16).photometric
    out = []
    for pose in poses:
        v_rig = pose_transform(pose).apply(vertices)
        img, cover = render_vertex_values(cam, RayCaster(v_rig, triangles), triangles, c * scale)
        img = np.exp(np.log(np.clip(img, 1e-6, 1.0)) / 2.2)
        img[~cover] = 1.0
        out.append(img)
    return out


def write_albedo_preview(path: str | os.PathLike, vertices: np.ndarray, triangles: np.ndarray,
                         maps: Sequence[tuple[str, np.ndarray, float]], *,
                         poses: Sequence[str] = ("frontal", "left", "right"),
                         resolution: int = 320, title: str = "") -> None:
    """Write a grid picture: one row per map, one column per pose.

    Parameters
    ----------
    path : path-like (.png)
    vertices, triangles : the mesh
    maps : sequence of (title, (n, 3) colours, scale)
    poses, resolution : see :func:`render_albedo_views`
    title : str
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    rows = len(maps)
    fig, axes = plt.subplots(rows, len(poses), figsize=(2.6 * len(poses), 2.6 * rows),
                             squeeze=False)
    for r, (name, colours, scale) in enumerate(maps):
        for c, img in enumerate(render_albedo_views(vertices, triangles, colours, poses=poses,
                                                    resolution=resolution, scale=scale)):
            ax = axes[r, c]
            ax.imshow(img, interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            if c == 0:
                ax.set_ylabel(name, fontsize=9)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=100)
    plt.close(fig)
