"""Write simulated lightstage captures in the capture-folder layout.

The layout is that of :mod:`pipeline.lightstage.capture_folder`.

``simulate_captures`` builds the procedural template head, a shape model, a
population of synthetic subjects (:mod:`pipeline.synthetic.subjects`) and the rig
(:mod:`pipeline.synthetic.dome`), then for every subject simulates its
three-pose polarised capture (:mod:`pipeline.synthetic.capture`) and writes the
images, the cameras, the registered mesh and the ground truth. Optionally it
also writes 3DRFE-like external scans: albedo maps from one view in another
colour space (:data:`EXTERNAL_COLOUR`), scaled by a per-scan ISO and encoded
with a pure 2.2 gamma in 8 bits.

Subject ``i`` depends only on ``(seed, i)``; a subject whose ``subject.json``
exists is skipped, so an interrupted run resumes. Subjects can be simulated
in parallel worker processes.

This module imports :mod:`albedo_model`, :mod:`pipeline.lightstage` (``camera_render``,
``capture_folder``, ``colour``), :mod:`pipeline.texturing.cameras` and :mod:`pipeline.synthetic`
modules (``capture``, ``dome``, ``subjects``, ``head``).
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from functools import lru_cache
from pathlib import Path

import numpy as np

from albedo_model.errors import InputError
from albedo_model.io.atomic import atomic_path
from albedo_model.io.image_io import write_png
from albedo_model.io.mesh_export import write_mesh
from pipeline.lightstage.capture_folder import (
    LightstageSpec,
    read_lightstage,
    write_json,
    write_lightstage,
    write_template,
)
from pipeline.texturing.cameras import LightstageCamera, StitchSettings
from pipeline.synthetic.dome import build_rig, camera_in_mesh_frame, pose_transform
from pipeline.lightstage.camera_render import render_vertex_values
from pipeline.synthetic.capture import (
    CaptureEffects,
    SimulationSettings,
    SubjectCapture,
    exposure_constant,
    simulate_capture,
    subject_raw_albedo,
)

__all__ = [
    "EXTERNAL_COLOUR", "cameras_json", "simulate_captures", "write_subject_capture",
]

#: Colour space of the simulated external scans: their linear maps are ``M_ext @ albedo``.
EXTERNAL_COLOUR = np.array([[0.62, 0.05, 0.0], [0.04, 0.55, 0.03], [0.0, 0.06, 0.5]])


def cameras_json(cameras: list[LightstageCamera], images: list[str],
                 stitching: StitchSettings | None = None) -> dict:
    """Return the camera-file object (:mod:`pipeline.texturing.cameras` format) of some views."""
    views = []
    for cam, image in zip(cameras, images):
        k1, k2, k3, p1, p2 = (float(x) for x in cam.distortion)
        h, w = cam.image_size
        views.append({
            "image": image,
            "T": np.hstack([cam.rotation, cam.translation[:, None]]).round(10).tolist(),
            "intrinsics": {"w": int(w), "h": int(h), "f": float(cam.focal_px),
                           "cx": float(cam.principal_px[0]), "cy": float(cam.principal_px[1]),
                           "k1": k1, "k2": k2, "k3": k3, "p1": p1, "p2": p2,
                           "tangential": "opencv", "pixel_origin": 0},
        })
    out = {"views": views}
    if stitching is not None:
        out["stitching"] = {"boundary_distance_px": stitching.boundary_distance_px,
                            "lambda": stitching.lam, "reference_view": stitching.reference_view}
    return out


def _write_tiff(path: Path, image: np.ndarray) -> None:
    import tifffile

    with atomic_path(path) as tmp:
        tifffile.imwrite(tmp, image, photometric="rgb", compression="zlib")


def write_subject_capture(folder: str | os.PathLike, capture: SubjectCapture,
                          triangles: np.ndarray, *, boundary_distance_px: float,
                          truth: tuple[np.ndarray, np.ndarray] | None = None) -> Path:
    """Write one subject's folder; ``subject.json`` is written last (marks it complete).

    Parameters
    ----------
    folder : path-like
        ``CAPTURES/subjects/<id>`` (created).
    capture : SubjectCapture
    triangles : (m, 3) int array
        Template triangles (for ``registered.ply``).
    boundary_distance_px : float
        Stored in ``cameras.json``.
    truth : (diffuse, specular), optional
        Ground truth, (n, 3) linear sRGB each, written to ``truth.npz``.
    """
    d = Path(folder)
    d.mkdir(parents=True, exist_ok=True)
    views = []
    for name, para, perp in zip(capture.poses, capture.parallel, capture.perpendicular):
        names = {"name": name, "parallel": f"{name}_parallel.tif",
                 "perpendicular": f"{name}_perpendicular.tif"}
        _write_tiff(d / names["parallel"], para)
        _write_tiff(d / names["perpendicular"], perp)
        views.append(names)
    write_json(d / "cameras.json", cameras_json(
        list(capture.cameras), [v["perpendicular"] for v in views],
        StitchSettings(boundary_distance_px=boundary_distance_px)))
    write_mesh(d / "registered.ply", capture.registered, triangles)
    meta = {"iso": capture.iso, "views": views, "registered": "registered.ply",
            "cameras": "cameras.json"}
    if capture.extra_images:
        (d / "multiview").mkdir(exist_ok=True)
        cams, files = [], []
        for name, pose_cams, images in zip(capture.poses, capture.extra_cameras,
                                           capture.extra_images):
            for k, (cam, img) in enumerate(zip(pose_cams, images)):
                rel = f"multiview/{name}_cam{k + 1}.png"
                write_png(d / rel, img.astype(np.float64) / 255.0)
                cams.append(cam)
                files.append(rel)
        write_json(d / "multiview.json", cameras_json(cams, files))
        meta["multiview"] = "multiview.json"
    if truth is not None:
        with atomic_path(d / "truth.npz") as tmp, open(tmp, "wb") as fh:
            np.savez_compressed(fh, diffuse=truth[0], specular=truth[1])
        meta["truth"] = "truth.npz"
    write_json(d / "subject.json", meta)
    return d


@dataclasses.dataclass(frozen=True)
class _Job:
    folder: str
    kind: str
    name: str
    vertices: np.ndarray
    triangles: np.ndarray
    raw_diffuse: np.ndarray
    raw_specular: np.ndarray
    truth_diffuse: np.ndarray
    truth_specular: np.ndarray
    seed: tuple[int, ...]
    settings: SimulationSettings
    effects: CaptureEffects


@lru_cache(maxsize=2)
def _worker_state(folder: str, resolution: int, extra_resolution: int, distortion: bool):
    spec = read_lightstage(folder)
    return build_rig(resolution=resolution, extra_resolution=extra_resolution,
                     distortion=distortion), spec.colour()


def _run_job(job: _Job) -> str:
    rig, colour = _worker_state(job.folder, job.settings.resolution,
                                job.settings.extra_resolution, job.effects.distortion)
    rng = np.random.default_rng(np.random.SeedSequence(job.seed[0], spawn_key=job.seed[1:]))
    out = Path(job.folder) / job.kind / job.name
    if job.kind == "subjects":
        cap = simulate_capture(job.vertices, job.triangles, job.raw_diffuse, job.raw_specular,
                               rig=rig, colour=colour, settings=job.settings,
                               effects=job.effects, rng=rng)
        write_subject_capture(out, cap, job.triangles,
                              boundary_distance_px=job.settings.boundary_distance_px,
                              truth=(job.truth_diffuse, job.truth_specular))
    else:
        _write_external(out, job, rig, rng)
    return job.name


def _write_external(out: Path, job: _Job, rig, rng: np.random.Generator) -> None:
    """Write a 3DRFE-like scan: gamma-encoded albedo maps seen by the frontal photometric camera."""
    from albedo_model.render.raycast import RayCaster

    out.mkdir(parents=True, exist_ok=True)
    pose = pose_transform("frontal", rng)
    v_rig = pose.apply(job.vertices)
    caster = RayCaster(v_rig, job.triangles)
    iso = int(rng.choice([100, 200]))
    gain = iso / 100.0
    for key, truth in (("diffuse", job.truth_diffuse), ("specular", job.truth_specular)):
        img, _ = render_vertex_values(rig.photometric, caster, job.triangles,
                                      gain * truth @ EXTERNAL_COLOUR.T)
        write_png(out / f"{key}.png", np.clip(img, 0.0, 1.0) ** (1.0 / 2.2))
    cam = camera_in_mesh_frame(rig.photometric, pose)
    write_json(out / "cameras.json", cameras_json(
        [cam], ["diffuse.png"], StitchSettings(job.settings.boundary_distance_px)))
    write_mesh(out / "registered.ply", job.vertices, job.triangles)
    with atomic_path(out / "truth.npz") as tmp, open(tmp, "wb") as fh:
        np.savez_compressed(fh, diffuse=job.truth_diffuse, specular=job.truth_specular)
    write_json(out / "scan.json", {"iso": iso, "gamma": 2.2, "diffuse": "diffuse.png",
                                   "specular": "specular.png", "registered": "registered.ply",
                                   "cameras": "cameras.json", "truth": "truth.npz"})


def _rig_spec(rig, colour_ref: dict, illuminant_ref: dict, colour, settings: SimulationSettings,
              effects: CaptureEffects) -> LightstageSpec:
    return LightstageSpec(
        camera=colour_ref, illuminant=illuminant_ref, raw_to_xyz="training",
        leds_mm=rig.leds_in_camera_frame(), led_intensity=np.ones(len(rig.leds)),
        centre_mm=rig.photometric.to_camera(np.zeros((1, 3)))[0],
        exposure=exposure_constant(colour, settings.white_level), iso_reference=100.0,
        polariser_transmission=settings.polariser_transmission, shading="leds",
        shadows=effects.shadows, specular_exponent=settings.specular_exponent)


def simulate_captures(
    folder: str | os.PathLike, n_subjects: int, *, seed: int = 0,
    settings: SimulationSettings | None = None,
    effects: CaptureEffects | None = None, camera: str | os.PathLike | None = None,
    illuminant: str = "LED-B4", n_external: int = 0, shape_rank: int = 20, jobs: int = 1,
    progress: Callable[[str], None] | None = None,
) -> Path:
    """Simulate a capture folder of ``n_subjects`` subjects (and ``n_external`` scans).

    Parameters
    ----------
    folder : path-like
        Created if missing. An existing folder must have been written with the
        same rig (its ``lightstage.json`` is replaced by an identical one).
    n_subjects : int
    seed : int
        Population seed (subjects, shapes, poses, noise).
    settings : SimulationSettings, optional
    effects : CaptureEffects, optional
        Default: every effect on.
    camera : str or path, optional
        A colour-science camera name (default ``"Nikon 5100 (NPL)"``) or a
        ``lambda,R,G,B`` CSV file (copied into the folder as ``camera.csv``).
    illuminant : str
        LED spectrum (a colour-science illuminant or light-source name).
    n_external : int
        Number of 3DRFE-like external scans (subjects after the captured ones).
    shape_rank : int
        Rank of the shape model the subjects' head shapes are drawn from.
    jobs : int
        Worker processes.
    progress : callable, optional
        Called with each finished subject's name.

    Returns
    -------
    Path of the folder.
    """
    from pipeline.lightstage.colour import DEFAULT_CAMERA
    from pipeline.synthetic.head.shape_model import build_shape_model
    from pipeline.synthetic.subjects import make_subjects
    from pipeline.synthetic.head.template_head import build_template_head

    settings = SimulationSettings() if settings is None else settings
    effects = CaptureEffects() if effects is None else effects
    if n_subjects < 0 or n_external < 0 or jobs < 1:
        raise InputError("numbers of subjects and scans must be >= 0 and jobs >= 1")
    root = Path(folder)
    root.mkdir(parents=True, exist_ok=True)
    cam_ref: dict = {"name": DEFAULT_CAMERA}
    if camera is not None and Path(camera).suffix.lower() == ".csv":
        shutil.copyfile(camera, root / "camera.csv")
        cam_ref = {"csv": "camera.csv"}
    elif camera is not None:
        cam_ref = {"name": str(camera)}
    rig = build_rig(resolution=settings.resolution, extra_resolution=settings.extra_resolution,
                    distortion=effects.distortion)
    provisional = LightstageSpec(camera=cam_ref, illuminant={"name": illuminant},
                                 raw_to_xyz="training", leds_mm=np.zeros((1, 3)),
                                 led_intensity=np.ones(1), centre_mm=np.zeros(3), exposure=1.0,
                                 folder=root)
    colour = provisional.colour()
    spec = _rig_spec(rig, cam_ref, {"name": illuminant}, colour, settings, effects)
    if (root / "lightstage.json").is_file() and any((root / "subjects").glob("*/subject.json")):
        old = read_lightstage(root).to_json()
        if json.dumps(old, sort_keys=True) != json.dumps(spec.to_json(), sort_keys=True):
            raise InputError(f"{root}: holds captures of a different rig or camera; "
                             "simulate into a new folder")
    write_lightstage(root, spec)
    head = build_template_head()
    write_template(root, head)
    todo = [("subjects", f"s{i:03d}", i) for i in range(n_subjects)]
    todo += [("external", f"e{j:03d}", n_subjects + j) for j in range(n_external)]
    marker = {"subjects": "subject.json", "external": "scan.json"}
    todo = [t for t in todo if not (root / t[0] / t[1] / marker[t[0]]).is_file()]
    if not todo:
        return root
    shape = build_shape_model(head, rank=shape_rank, seed=seed)
    population = make_subjects(head, n_subjects + n_external, seed)
    eyes = head.regions["eyeballs"]
    jobs_list = []
    for kind, name, index in todo:
        subj = population[index]
        rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(2, index)))
        coef = rng.standard_normal(shape.rank) * np.sqrt(shape.variance)
        verts = (shape.mean + shape.basis @ coef).reshape(-1, 3)
        raw_d, raw_s = subject_raw_albedo(subj.melanin, subj.blood, subj.diffuse, subj.specular,
                                          eyes, colour)
        jobs_list.append(_Job(str(root), kind, name, verts, head.triangles, raw_d, raw_s,
                              np.asarray(subj.diffuse), np.asarray(subj.specular),
                              (seed, 3, index), settings, effects))
    say = progress or (lambda name: None)
    if jobs == 1:
        for job in jobs_list:
            say(_run_job(job))
    else:
        import multiprocessing

        ctx = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(max_workers=jobs, mp_context=ctx) as pool:
            for name in pool.map(_run_job, jobs_list):
                say(name)
    return root
