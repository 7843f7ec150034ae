"""A tiny LFW-like tree of synthetic faces for batch tests: ``Name/Name_0001.png`` + ``.tlms``."""

from __future__ import annotations

from pathlib import Path

from albedo_model.io.image_io import write_png
from albedo_model.io.tlms import Landmark, write_tlms
from mcmcfit.jobs.synthetic_case import synthetic_case

SUBJECTS = ("Ann_Alpha", "Bob_Beta", "Cy_Gamma")


def write_case(model, image_path: Path, *, seed: int, size: int) -> Path:
    """Render one synthetic case and write its PNG with the true landmarks beside it (.tlms)."""
    case = synthetic_case(model, seed=seed, size=size)
    image_path.parent.mkdir(parents=True, exist_ok=True)
    write_png(image_path, case.image)
    write_tlms(image_path.with_suffix(".tlms"),
               [Landmark(n, tuple(float(v) for v in p), True) for n, p in case.landmarks.items()])
    return image_path


def lfw_like_tree(model, root: Path, n_images: int, *, size: int = 96) -> list[Path]:
    """``n_images`` synthetic faces laid out like LFW, subjects in turn; returns the PNG paths."""
    paths = []
    for i in range(n_images):
        subject = SUBJECTS[i % len(SUBJECTS)]
        number = i // len(SUBJECTS) + 1
        paths.append(write_case(model, root / subject / f"{subject}_{number:04d}.png",
                                seed=100 + i, size=size))
    return paths
