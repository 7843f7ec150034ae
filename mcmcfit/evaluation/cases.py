"""The evaluation's inputs: models built without the held-out subjects, and their photographs.

:func:`prepare_cases` writes, under the evaluation folder ``EVAL``::

    EVAL/models/<name>.h5               the models fitted (:data:`MODEL_VARIANTS`)
    EVAL/cases/<scene>/<subject>.jpg    the photographs (.png without JPEG) and their
    EVAL/cases/<scene>/<subject>.tlms   noisy landmarks: the batch engine's input tree
    EVAL/truth/<scene>/<subject>.npz    true diffuse and specular albedo, visible vertices
    EVAL/truth/<scene>/<subject>.rps    the true scene
    EVAL/cases.json                     settings, models (file, SHA-256, colour space),
                                        one record per case (projection floors, effects,
                                        render timings)

It is resumable: an existing ``cases.json`` made with the same settings is
reused as is (the models and photographs are deterministic in the
settings); one made with other settings is an error, so nothing already
written is lost.

This module imports :mod:`albedo_model` (errors, file formats) and
:mod:`pipeline.synthetic` (held-out population, skin detail, baked model,
scenes); those are imported when the cases are made.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from albedo_model.errors import InputError

__all__ = ["CASES_FILE", "MODEL_VARIANTS", "case_settings", "check_scene_subjects", "load_cases",
           "prepare_cases"]

#: The models an evaluation can fit: file name, the colour space the fit reads its
#: colour in (``FitConfig.model_colour``), and what it is.
MODEL_VARIANTS = {
    "intrinsic": {"file": "intrinsic.h5", "model_colour": "linear",
                  "label": "intrinsic albedo model (ours)"},
    "baked": {"file": "baked.h5", "model_colour": "srgb",
              "label": "baked textures, colour taken as camera sRGB (the reference's way)"},
    "baked-gamma": {"file": "baked-gamma.h5", "model_colour": "linear",
                    "label": "baked textures decoded to linear ('we applied gamma for both')"},
}

CASES_FILE = "cases.json"


def case_settings(*, n_subjects: int, n_held_out: int, scenes, models, size: int, seed: int,
                  detail: dict) -> dict:
    """Return the settings that determine the cases (compared on resume)."""
    return {"n_subjects": int(n_subjects), "n_held_out": int(n_held_out),
            "scenes": list(scenes), "models": list(models), "size": int(size),
            "seed": int(seed), "detail": dict(detail)}


def load_cases(root: Path) -> dict | None:
    """Return ``EVAL/cases.json``, or None when there is none."""
    path = Path(root) / CASES_FILE
    if not path.is_file():
        return None
    return json.loads(path.read_text(encoding="utf-8"))


def _write_json(path: Path, data: dict) -> None:
    from albedo_model.io.atomic import atomic_path

    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(data, indent=1, default=float), encoding="utf-8")


def _write_models(root: Path, population, models, say) -> dict:
    from albedo_model.io.model_files import file_sha256
    from albedo_model.io.momo_h5 import write_model_h5
    from pipeline.synthetic.baked_model import build_baked_model

    folder = root / "models"
    folder.mkdir(parents=True, exist_ok=True)
    built, out = {}, {}
    for name in models:
        spec = MODEL_VARIANTS[name]
        say(f"model {name}")
        if name == "intrinsic":
            model = population.model
        else:
            model = build_baked_model(population.model, population.training,
                                      population.albedo_rank,
                                      colour="srgb" if name == "baked" else "linear")
        path = folder / spec["file"]
        write_model_h5(model, path)
        built[name] = model
        out[name] = {"file": str(path.relative_to(root)), "sha256": file_sha256(path),
                     "model_colour": spec["model_colour"], "rank": model.ranks["diffuse"],
                     "label": spec["label"]}
    return built, out


def _floors(models: dict, truth_d: np.ndarray, truth_s: np.ndarray, visible: np.ndarray) -> dict:
    from pipeline.synthetic.skin_detail import projection_floor

    out = {}
    for name, model in models.items():
        colour = "srgb" if name == "baked" else "linear"
        out[name] = {"diffuse": projection_floor(model.diffuse, truth_d, visible, colour=colour)}
        if model.specular is not None:
            out[name]["specular"] = projection_floor(model.specular, truth_s, visible)
    return out


def _write_case(root: Path, scene: str, subject, photo, floors: dict) -> dict:
    from albedo_model.io.rps import write_rps
    from albedo_model.io.tlms import Landmark, write_tlms

    name = f"subject{subject.index:03d}"
    cases = root / "cases" / scene
    truth = root / "truth" / scene
    cases.mkdir(parents=True, exist_ok=True)
    truth.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(truth / f"{name}.npz", diffuse=subject.diffuse.astype(np.float32),
                        specular=subject.specular.astype(np.float32), visible=photo.visible,
                        colour_matrix=photo.colour_matrix)
    write_rps(truth / f"{name}.rps", photo.truth)
    write_tlms(cases / f"{name}.tlms", [Landmark(n, (float(p[0]), float(p[1])), True)
                                       for n, p in photo.landmarks.items()])
    (cases / f"{name}{photo.suffix}").write_bytes(photo.encoded)  # last: the batch's input
    return {"scene": scene, "case": f"{scene}/{name}", "subject": subject.index,
            "fitzpatrick": subject.fitzpatrick, "detail": subject.detail,
            "image": f"cases/{scene}/{name}{photo.suffix}",
            "truth": f"truth/{scene}/{name}.npz", "truth_rps": f"truth/{scene}/{name}.rps",
            "n_visible": int(photo.visible.sum()), "n_landmarks": len(photo.landmarks),
            "effects": photo.computed, "render_timings": photo.timings,
            "projection_floor": floors}


def check_scene_subjects(specs: dict, n_subjects: int, n_held_out: int) -> None:
    """InputError when a scene photographs no held-out subject (its Fitzpatrick types).

    Subject ``i`` has type ``i mod 6 + 1`` (:mod:`pipeline.synthetic.subjects`).
    """
    from pipeline.synthetic.held_out import held_out_indices

    types = sorted({i % 6 + 1 for i in held_out_indices(n_subjects, n_held_out)})
    for name, spec in specs.items():
        if not set(types) & set(spec.fitzpatrick):
            raise InputError(f"scene {name!r} photographs Fitzpatrick types "
                             f"{list(spec.fitzpatrick)}; the held-out subjects have types "
                             f"{types} (subject i has type i mod 6 + 1): use --held-out 6")


def prepare_cases(root: Path, settings: dict, *, log=None) -> dict:
    """Build (or reuse) the models and photographs of an evaluation; return ``cases.json``.

    Parameters
    ----------
    root : Path
        The evaluation folder ``EVAL``.
    settings : dict
        :func:`case_settings`.
    log : callable ``(str) -> None``, optional

    Returns
    -------
    dict
        ``settings``, ``models`` (name -> file, sha256, model_colour, rank),
        ``cases`` (one record per case), ``version``.

    Raises
    ------
    InputError
        ``cases.json`` exists with other settings; a scene has no subject of its
        Fitzpatrick types among the held-out subjects.
    """
    from mcmcfit.outputs.summary import software_versions
    from pipeline.synthetic.held_out import build_held_out_population
    from pipeline.synthetic.scene_render import render_scene
    from pipeline.synthetic.scenes import scene_spec
    from pipeline.synthetic.skin_detail import SkinDetail

    say = log or (lambda text: None)
    root = Path(root)
    old = load_cases(root)
    if old is not None:
        if old.get("settings") != settings:
            raise InputError(f"{root} holds an evaluation made with other settings "
                             f"({old.get('settings')}); use another -o folder (nothing "
                             "was changed)")
        return old
    specs = {s: scene_spec(s) for s in settings["scenes"]}
    check_scene_subjects(specs, settings["n_subjects"], settings["n_held_out"])
    say("building the held-out population and the models")
    population = build_held_out_population(
        settings["n_subjects"], settings["n_held_out"], seed=settings["seed"],
        detail=SkinDetail(**settings["detail"]))
    root.mkdir(parents=True, exist_ok=True)
    models, model_records = _write_models(root, population, settings["models"], say)
    records = []
    for s, spec in specs.items():
        say(f"rendering scene {s}")
        for h in population.held_out:
            if h.fitzpatrick not in spec.fitzpatrick:
                continue
            photo = render_scene(population.model, h.diffuse, h.specular, spec,
                                 seed=[settings["seed"], 13, h.index, list(specs).index(s)],
                                 size=settings["size"])
            floors = _floors(models, h.diffuse, h.specular, photo.visible)
            records.append(_write_case(root, s, h, photo, floors) | {"scene_spec": spec.to_dict()})
    data = {"settings": settings, "software": software_versions(), "models": model_records,
            "population": {"training": list(range(settings["n_subjects"])),
                           "held_out": [h.index for h in population.held_out],
                           "albedo_rank": population.albedo_rank},
            "cases": records}
    _write_json(root / CASES_FILE, data)
    return data
