"""Micro-benchmark: forming the camera's rays after a camera move, eye-frame grid against affine map.

Every ray cast of the sampler (the renderer's window, the gradient's region
pixels) first forms one ray per pixel in the model frame
(:func:`albedo_model.camera.camera_rays`). The previous version built the
eye-frame grid of ray origins and directions, cached by focal length and
principal point, and mapped it by the pose: but the focal length is sampled,
so nearly every geometry move missed that cache and rebuilt the (H W, 4) grid.
A ray is affine in its pixel's coordinates, so the current version maps a
cached ``(i, j, 1)`` grid by one (3, 3) matrix per array, whatever the camera.

This times both after a change of focal length (the sampler's case), for all
pixels of a 250x250 image and for a 15,800-pixel region (the gradient's ray
cast), called round-robin so that machine load affects them alike, and prints
the ratio and the largest difference between them.

Usage: ``python benchmarks/bench_camera_rays.py [--reps 400]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from albedo_model.camera import _eye_rays, camera_rays, eye_from_model
from albedo_model.params import Camera, ImageSize, Pose, View


def grid_rays(camera, size, pose, view, pixels=None):
    """The previous path: the eye-frame grid (rebuilt for a new camera), mapped by the pose."""
    org, dirs = _eye_rays(camera, size)
    if pixels is not None:
        org, dirs = org[pixels], dirs[pixels]
    r, t, s = eye_from_model(pose, view)
    m = np.empty((4, 3), np.float32)
    m[:3] = r / s
    m[3] = -(t @ r) / s
    return org @ m, dirs @ m


def main(argv: list[str] | None = None) -> None:
    """Time both ways of forming the rays after focal-length moves; print the ratios."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=400)
    args = ap.parse_args(argv)
    size = ImageSize(250, 250)
    view = View()
    pose = Pose(yaw=0.3, pitch=-0.1, roll=0.05, translation=(5.0, 3.0, -1150.0))
    rng = np.random.default_rng(0)
    region = np.sort(rng.choice(size.width * size.height, 15_800, replace=False))
    for label, pixels in (("all 62,500 pixels", None), ("a 15,800-pixel region", region)):
        times = {"grid (before)": [], "affine (now)": []}
        worst = 0.0
        for k in range(args.reps):
            camera = Camera()._replace(focal_length=Camera().focal_length * (1.0 + 1e-4 * k))
            t0 = time.perf_counter()
            o0, d0 = grid_rays(camera, size, pose, view, pixels)
            t1 = time.perf_counter()
            o1, d1 = camera_rays(camera, size, pose, view, pixels=pixels)
            t2 = time.perf_counter()
            times["grid (before)"].append(t1 - t0)
            times["affine (now)"].append(t2 - t1)
            worst = max(worst, float(np.abs(d1 - d0).max()),
                        float(np.abs(o1 - o0).max() / np.abs(o0).max()))
        med = {k: 1e3 * float(np.median(v)) for k, v in times.items()}
        print(f"{label}: " + ", ".join(f"{k} {v:.3f} ms" for k, v in med.items())
              + f"; ratio {med['grid (before)'] / med['affine (now)']:.2f}x; largest difference "
              f"{worst:.1e} (directions; origins relative)")


if __name__ == "__main__":
    main()
