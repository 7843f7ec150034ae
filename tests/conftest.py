"""Shared test fixtures."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``../shared/data`` beside the repository; skips when absent (users' machines)."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"shared test data not found at {SHARED_DATA}")
    return SHARED_DATA


# -- stand-in template head (pipeline tests) -----------------------------------

HEAD_RADII_MM = np.array([75.0, 100.0, 90.0])


@dataclasses.dataclass(frozen=True)
class StandInHead:
    """Same attributes as ``pipeline.synthetic.head.template_head.TemplateHead``."""

    vertices: np.ndarray
    triangles: np.ndarray
    symmetry: np.ndarray
    landmarks: dict
    regions: dict


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def make_stand_in_head(subdivisions: int = 4) -> StandInHead:
    """An ellipsoidal 'head' (+x subject's left, +y up, +z toward the viewer), fake regions."""
    import trimesh
    from scipy.spatial import cKDTree

    sphere = trimesh.creation.icosphere(subdivisions=subdivisions)
    u = np.asarray(sphere.vertices, float)
    v = u * HEAD_RADII_MM
    mirrored = u * np.array([-1.0, 1.0, 1.0])
    dist, symmetry = cKDTree(u).query(mirrored)
    assert dist.max() < 1e-9
    ax, uy, uz = np.abs(u[:, 0]), u[:, 1], u[:, 2]
    front = uz > 0.3
    eye_centres = [_unit([s * 0.33, 0.18, 0.92]) for s in (1.0, -1.0)]
    eyeballs = np.zeros(len(u), bool)
    for c in eye_centres:
        eyeballs |= np.linalg.norm(u - c, axis=1) < 0.11
    regions = {
        "eyeballs": eyeballs,
        "brows": front & (np.abs(ax - 0.33) < 0.16) & (np.abs(uy - 0.37) < 0.05),
        "nose": (ax < 0.1) & (uy > -0.2) & (uy < 0.15) & (uz > 0.9),
        "lips": (ax < 0.2) & (uy > -0.46) & (uy < -0.34) & front,
        "forehead": (uy > 0.45) & (uz > 0.5),
        "cheeks": (ax > 0.2) & (ax < 0.55) & (uy > -0.35) & (uy < 0.08) & front,
        "beard": (uy < -0.3) & (uz > 0.2),
        "ears": (ax > 0.9) & (np.abs(uy) < 0.25),
    }
    regions["skin"] = ~eyeballs
    landmarks = {
        "left.eye.pupil.center": int(np.argmin(np.linalg.norm(u - eye_centres[0], axis=1))),
        "right.eye.pupil.center": int(np.argmin(np.linalg.norm(u - eye_centres[1], axis=1))),
        "center.nose.tip": int(np.argmax(uz)),
    }
    return StandInHead(v, np.asarray(sphere.faces, np.int64), symmetry, landmarks, regions)


@pytest.fixture(scope="session")
def stand_in_head() -> StandInHead:
    """A 2562-vertex stand-in for ``pipeline.synthetic.head.template_head.TemplateHead``."""
    return make_stand_in_head()


@pytest.fixture(scope="session")
def shared_cache(tmp_path_factory) -> Path:
    """The run's mcmcfit cache (``MCMCFIT_CACHE``), one for all pytest-xdist workers.

    The workers share the built default model (built once per run, not once per
    worker) and, in the fits that run after it is set, XLA's compiled programs
    (:func:`mcmcfit.fitting.chain_session.use_compilation_cache` keeps them in ``<cache>/jax``).
    """
    base = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        base = base.parent  # the run's temporary root, common to its workers
    cache = base / "mcmcfit-cache"
    cache.mkdir(exist_ok=True)
    return cache


@pytest.fixture(scope="session")
def default_model_file(shared_cache) -> Path:
    """The real built-in default model, built once per test run into the run's cache.

    Sets ``MCMCFIT_CACHE`` for the session so that ``default`` resolves to it;
    the first worker to get here builds the model while the others wait.
    """
    import fcntl

    from pipeline.synthetic.default_model import ensure_default_model

    old = os.environ.get("MCMCFIT_CACHE")
    os.environ["MCMCFIT_CACHE"] = str(shared_cache)
    try:
        with open(shared_cache / "default-model.lock", "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            path = ensure_default_model(progress=False)
        yield path
    finally:
        if old is None:
            os.environ.pop("MCMCFIT_CACHE", None)
        else:
            os.environ["MCMCFIT_CACHE"] = old
