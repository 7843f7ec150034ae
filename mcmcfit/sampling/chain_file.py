r"""The chain file ``chain.h5``: every stage of every chain, with the fit's fixed fields.

:func:`write_chains_h5` writes :class:`~mcmcfit.sampling.chain.ChainRecord`\ s with
``emcee``'s vocabulary in mind (``get_chain``-style arrays: samples (n, d) per
chain and stage); :func:`read_chains_h5` reads them back. A joint fit's file
(several photographs of one face, :mod:`mcmcfit.sampling.joint_layout`) has
one template per photograph (``template_rps_images``, a JSON list) instead of
``template_rps``, and reads back with its joint layout and states.

This module imports :mod:`albedo_model` (errors, params, io.rps, io.atomic),
:mod:`mcmcfit.sampling` (chain, joint_layout, param_vector) and :mod:`proposals.joint`.
"""

from __future__ import annotations

import json
import os

import numpy as np

from albedo_model.errors import FormatError
from albedo_model.io.atomic import atomic_path
from albedo_model.io.rps import format_rps_text, parse_rps_text
from albedo_model.params import RenderParameter
from mcmcfit.sampling.chain import BestSample, ChainRecord, ChainResult
from mcmcfit.sampling.joint_layout import JointParamLayout
from mcmcfit.sampling.param_vector import ParamLayout
from proposals.joint import JointParameter

__all__ = ["CHAIN_FILE_VERSION", "read_chains_h5", "template_attrs", "template_from_attrs",
           "write_chains_h5"]

CHAIN_FILE_VERSION = "1"


def _write_record(g, rec: ChainRecord) -> None:
    g.attrs.update(stage=rec.stage, sampler=rec.sampler, thin=rec.thin, steps=rec.steps,
                   seconds=rec.seconds, extra=json.dumps(rec.extra, default=float))
    for name in ("sample_step", "samples", "log_prior", "log_lik_lm", "log_lik_img", "proposal",
                 "accepted", "rejected_by", "step_seconds"):
        g.create_dataset(name, data=getattr(rec, name), compression="gzip", compression_opts=4)
    g.create_dataset("proposal_names", data=np.array(rec.proposal_names, dtype=object),
                     dtype=_str_dtype())
    for which in ("best_image", "best_landmarks", "best_posterior"):
        b: BestSample = getattr(rec, which)
        ds = g.create_dataset(which, data=rec.layout.to_vector(b.params))
        ds.attrs.update(step=b.step, log_prior=b.log_prior, log_lik_lm=b.log_lik_lm,
                        log_lik_img=b.log_lik_img)


def template_attrs(template: RenderParameter | JointParameter) -> dict[str, str]:
    """Return the fixed fields of a fit as text attributes (``template_rps`` or ``template_rps_images``)."""
    if isinstance(template, JointParameter):
        return {"template_rps_images": json.dumps([format_rps_text(p) for p in template.images])}
    return {"template_rps": format_rps_text(template)}


def template_from_attrs(attrs, source: str | os.PathLike = "<attrs>"
                        ) -> tuple[RenderParameter | JointParameter, ParamLayout | JointParamLayout]:
    """Read back :func:`template_attrs`: the template and its column layout.

    Raises
    ------
    FormatError
        Neither attribute is there.
    """
    if "template_rps_images" in attrs:
        texts = json.loads(str(attrs["template_rps_images"]))
        joint = JointParameter.share([parse_rps_text(t, source=source) for t in texts])
        return joint, JointParamLayout.for_params(joint)
    if "template_rps" not in attrs:
        raise FormatError(source, "no template_rps attribute (the fit's fixed fields)")
    template = parse_rps_text(str(attrs["template_rps"]), source=source)
    return template, ParamLayout.for_params(template)


def _str_dtype():
    import h5py

    return h5py.string_dtype("utf-8")


def write_chains_h5(path: str | os.PathLike, chains: list[ChainResult],
                    layout: ParamLayout | JointParamLayout,
                    template: RenderParameter | JointParameter, *,
                    attrs: dict | None = None) -> None:
    """Write chain records to HDF5 (atomically).

    Layout: root attrs ``version``, ``template_rps`` (the fixed fields, .rps V4
    JSON; a joint fit: ``template_rps_images``, one per photograph) and
    ``attrs`` (e.g. ``config`` JSON, ``seed``); ``/parameter_names``;
    ``/chain_<i>/{stage1,warmup,stage2}/`` with the :class:`ChainRecord` arrays and
    ``best_*`` vectors (attrs: step and log densities).
    """
    import h5py

    with atomic_path(path, suffix=".h5") as tmp, h5py.File(tmp, "w") as f:
        f.attrs["version"] = CHAIN_FILE_VERSION
        f.attrs.update(template_attrs(template))
        for k, v in (attrs or {}).items():
            f.attrs[k] = v
        f.create_dataset("parameter_names", data=np.array(layout.names, dtype=object),
                         dtype=_str_dtype())
        for c in chains:
            g = f.create_group(f"chain_{c.index:03d}")
            g.attrs.update(seed_entropy=str(c.seed_entropy), spawn_key=list(c.spawn_key))
            for name in ("stage1", "warmup", "stage2"):
                rec = getattr(c, name)
                if rec is not None:
                    _write_record(g.create_group(name), rec)


def _read_record(g, layout: ParamLayout | JointParamLayout,
                 template: RenderParameter | JointParameter) -> ChainRecord:
    def best(name: str) -> BestSample:
        ds = g[name]
        a = ds.attrs
        return BestSample(layout.from_vector(ds[()], template), int(a["step"]),
                          float(a["log_prior"]), float(a["log_lik_lm"]), float(a["log_lik_img"]))

    names = tuple(s.decode() if isinstance(s, bytes) else str(s) for s in g["proposal_names"][()])
    return ChainRecord(
        str(g.attrs["stage"]), str(g.attrs["sampler"]), int(g.attrs["thin"]),
        int(g.attrs["steps"]), layout, g["sample_step"][()], g["samples"][()],
        g["log_prior"][()], g["log_lik_lm"][()], g["log_lik_img"][()], g["proposal"][()], names,
        g["accepted"][()], g["rejected_by"][()], best("best_image"), best("best_landmarks"),
        best("best_posterior"), float(g.attrs["seconds"]), json.loads(g.attrs["extra"]),
        g["step_seconds"][()] if "step_seconds" in g else np.zeros(0, np.float32))


def read_chains_h5(path: str | os.PathLike
                   ) -> tuple[list[ChainResult], ParamLayout | JointParamLayout, dict]:
    """Read a file of :func:`write_chains_h5`: ``(chains, layout, root attrs)``.

    A joint fit's file gives a :class:`~mcmcfit.sampling.joint_layout.JointParamLayout`
    and :class:`~proposals.joint.JointParameter` best states.

    Raises
    ------
    FormatError
        Not a chain file, or an unknown version.
    """
    import h5py

    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise FormatError(path, f"not an HDF5 file ({exc})") from None
    with f:
        if f.attrs.get("version") != CHAIN_FILE_VERSION or "parameter_names" not in f:
            raise FormatError(path, "not an mcmcfit chain file (version 1)")
        template, layout = template_from_attrs(f.attrs, source=path)
        names = tuple(s.decode() if isinstance(s, bytes) else str(s)
                      for s in f["parameter_names"][()])
        if names != layout.names:
            raise FormatError(path, "parameter names do not match the stored template")
        chains = []
        for key in sorted(k for k in f if k.startswith("chain_")):
            g = f[key]
            chains.append(ChainResult(
                int(key.split("_")[1]), int(g.attrs["seed_entropy"]),
                tuple(int(x) for x in g.attrs["spawn_key"]),
                _read_record(g["stage1"], layout, template) if "stage1" in g else None,
                _read_record(g["stage2"], layout, template) if "stage2" in g else None,
                _read_record(g["warmup"], layout, template) if "warmup" in g else None))
        attrs = {k: v for k, v in f.attrs.items()
                 if k not in ("version", "template_rps", "template_rps_images")}
    return chains, layout, attrs

