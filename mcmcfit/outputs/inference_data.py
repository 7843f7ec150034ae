"""``posterior.nc``: the chains of a fit as an ArviZ ``InferenceData`` (netCDF, h5netcdf).

Groups (dimensions ``chain`` and ``draw`` first; one draw per kept sample):

``posterior``
    Every sampled parameter, one variable per block of
    :class:`~mcmcfit.sampling.param_vector.ParamLayout`: ``pose`` (``pose_param``:
    yaw, pitch, roll in rad, tx, ty, tz in mm, scaling), ``camera``
    (``camera_param``), ``light`` (``sh_coefficient`` x ``channel``),
    ``color_transform`` (``color_transform_param``), ``specular_exponent``,
    ``shape`` / ``albedo`` / ``expression`` (``<block>_coefficient``), and the
    derived ``albedo_mean`` (``region`` x ``channel``: the area-weighted mean
    linear diffuse albedo of each face region, :mod:`mcmcfit.sampling.derived`).
``sample_stats``
    Of the state each draw is: ``lp`` (log posterior), ``log_likelihood_image``,
    ``log_likelihood_landmarks``, ``log_prior``, ``acceptance_rate`` (fraction of
    the steps since the previous draw that were accepted), ``proposal`` (index
    into the variable's ``proposal_names`` attribute, the move of the draw's
    step) and ``step`` (the step index in its stage).
``warmup_posterior``, ``warmup_sample_stats``
    The same for the image stage's warm-up (the chains' ``warmup`` records when
    they have one; else the leading ``burn_fraction`` of the kept draws).
``observed_data``
    ``image`` (``y`` x ``x`` x ``channel``, the target as fitted) and
    ``landmarks`` (``landmark`` x ``xy``, pixels), when given.

Every group carries the ``attrs`` passed in (seed, model hash, software versions,
noise model, ...; nested values as JSON text) and ``template_rps``, the fixed
parameter fields (.rps V4 JSON) that turn a draw back into parameters.

A joint fit (several photographs of one face) stores its per-photograph
blocks with an ``image`` dimension and each photograph's observed image and
landmarks as ``image<k>`` / ``landmarks<k>``.

This module imports :mod:`albedo_model` (io.atomic, model, params),
:mod:`mcmcfit.sampling` (chain, chain_file, derived, diagnostics, joint_layout,
param_vector) and :mod:`proposals.joint`.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence

import numpy as np

from albedo_model.io.atomic import atomic_path
from albedo_model.model import MorphableModel
from albedo_model.params import RenderParameter
from mcmcfit.sampling.chain import ChainRecord, ChainResult
from mcmcfit.sampling.chain_file import template_attrs
from mcmcfit.sampling.derived import RegionAlbedo, region_albedo_basis, region_albedo_means
from mcmcfit.sampling.diagnostics import arviz
from mcmcfit.sampling.joint_layout import JointParamLayout
from mcmcfit.sampling.param_vector import ParamLayout
from proposals.joint import JointParameter

__all__ = ["POSTERIOR_FILE", "inference_data", "write_posterior_nc"]

#: File name in the result folder.
POSTERIOR_FILE = "posterior.nc"

_COEFFICIENT_BLOCKS = ("shape", "albedo", "expression")


def _blocks(layout: ParamLayout | JointParamLayout) -> dict[str, tuple[np.ndarray, list[str]]]:
    """Variable name -> (columns, coordinate labels) in layout order.

    The columns are (m,) for a variable of the whole fit and (n_images, m) for
    a joint fit's per-photograph block (columns ``image<k>.<block>.<label>``).
    """
    found: dict[str, dict[int | None, tuple[list[int], list[str]]]] = {}
    for j, name in enumerate(layout.names):
        image = None
        head, _, rest = name.partition(".")
        if head.startswith("image") and head[5:].isdigit():
            image = int(head[5:])
            head, _, rest = rest.partition(".")
        cols, labels = found.setdefault(head, {}).setdefault(image, ([], []))
        cols.append(j)
        labels.append(rest.replace(".", "_"))
    out: dict[str, tuple[np.ndarray, list[str]]] = {}
    for var, per in found.items():
        if None in per:
            out[var] = (np.array(per[None][0]), per[None][1])
        else:
            out[var] = (np.array([per[k][0] for k in sorted(per)]), per[min(per)][1])
    return out


def _posterior_vars(kept: np.ndarray, layout: ParamLayout | JointParamLayout,
                    basis: RegionAlbedo | None) -> dict:
    """Return the posterior ``data_vars`` of (chains, draws, d) kept samples."""
    data: dict = {}
    for var, (cols, labels) in _blocks(layout).items():
        x = kept[:, :, cols]  # (c, n, m) or (c, n, images, m)
        lead = ("chain", "draw") + (("image",) if cols.ndim == 2 else ())
        if var == "light":
            data[var] = (lead + ("sh_coefficient", "channel"),
                         x.reshape(*x.shape[:-1], x.shape[-1] // 3, 3))
        elif labels == [""]:
            data[var] = (lead, x[..., 0])
        elif var in _COEFFICIENT_BLOCKS:
            data[var] = (lead + (f"{var}_coefficient",), x)
        else:
            data[var] = (lead + (f"{var}_param",), x)
    if basis is not None and basis.regions and layout.n_albedo:
        data["albedo_mean"] = (("chain", "draw", "region", "channel"),
                               region_albedo_means(kept[:, :, layout.slice("albedo")], basis))
    return data


def _coords(layout: ParamLayout | JointParamLayout, basis: RegionAlbedo | None) -> dict:
    blocks = _blocks(layout)
    coords: dict = {"channel": ["r", "g", "b"]}
    if "light" in blocks:
        coords["sh_coefficient"] = np.arange(len(blocks["light"][1]) // 3)
    if isinstance(layout, JointParamLayout):
        coords["image"] = np.arange(layout.n_images)
    for var, (_, labels) in blocks.items():
        if var in _COEFFICIENT_BLOCKS:
            coords[f"{var}_coefficient"] = np.arange(len(labels))
        elif var != "light" and labels != [""]:
            coords[f"{var}_param"] = labels
    if basis is not None and basis.regions:
        coords["region"] = list(basis.regions)
    return coords


def _window_acceptance(rec: ChainRecord, steps: np.ndarray) -> np.ndarray:
    """Fraction of accepted steps in (previous draw's step, this draw's step], per draw."""
    cs = np.concatenate([[0], np.cumsum(rec.accepted.astype(np.int64))])
    hi = steps + 1
    lo = np.concatenate([[0], hi[:-1]])
    n = np.maximum(hi - lo, 1)
    return (cs[hi] - cs[lo]) / n


def _stats_vars(recs: Sequence[ChainRecord], start: int, stop: int,
                names: list[str]) -> dict:
    """Return the ``data_vars`` of the per-draw sample statistics of draws [start, stop)."""
    cols: dict[str, list[np.ndarray]] = {k: [] for k in (
        "lp", "log_likelihood_image", "log_likelihood_landmarks", "log_prior",
        "acceptance_rate", "proposal", "step")}
    for r in recs:
        steps = np.asarray(r.sample_step[:stop], np.int64)
        if r.steps > 0:
            idx = np.clip(steps, 0, r.steps - 1)
            acc = _window_acceptance(r, idx)
            remap = np.array([names.index(p) for p in r.proposal_names] or [0], np.int32)
            prop = remap[r.proposal[idx]] if r.proposal.size else np.full(len(idx), -1)
            dens = [r.log_posterior[idx], r.log_lik_img[idx], r.log_lik_lm[idx],
                    r.log_prior[idx]]
        else:  # emcee: log densities per kept sample
            acc = np.full(stop, np.nan)
            prop = np.full(stop, -1, np.int32)
            dens = [r.log_posterior[:stop], r.log_lik_img[:stop], r.log_lik_lm[:stop],
                    r.log_prior[:stop]]
        for k, v in zip(cols, [*dens, acc, prop, steps]):
            cols[k].append(np.asarray(v)[start:stop])
    return {k: (("chain", "draw"), np.stack(v) if v else np.zeros((0, 0))) for k, v in cols.items()}


def _attrs(attrs: Mapping | None, template: RenderParameter | JointParameter) -> dict:
    out = {"created_by": "mcmcfit", **template_attrs(template)}
    for k, v in (attrs or {}).items():
        if isinstance(v, (str, int, float, np.integer, np.floating)) and not isinstance(v, bool):
            out[str(k)] = v
        else:
            out[str(k)] = json.dumps(v, default=str)
    return out


def _dataset(data: dict, coords: dict, draws: np.ndarray, chains: np.ndarray, attrs: dict):
    import xarray as xr

    used = {d for dims, _ in data.values() for d in dims}
    c = {k: v for k, v in coords.items() if k in used}
    return xr.Dataset(data, coords={**c, "chain": chains, "draw": draws}, attrs=attrs)


def _observed_vars(image, landmarks: Mapping | None, suffix: str = "") -> tuple[dict, dict]:
    """One photograph's observed variables (``image``, ``landmarks``), names ending in ``suffix``."""
    data, coords = {}, {}
    if image is not None:
        img = np.asarray(image, np.float64)
        dims = ("y", "x") if not suffix else (f"y{suffix}", f"x{suffix}")
        data[f"image{suffix}"] = (dims + ("channel",), img)
        coords["channel"] = ["r", "g", "b"][:img.shape[2]]
    if landmarks:
        names = sorted(landmarks)
        dim = f"landmark{suffix}"
        data[f"landmarks{suffix}"] = ((dim, "xy"), np.array(
            [np.asarray(landmarks[n], np.float64)[:2] for n in names]))
        coords.update({dim: names, "xy": ["x", "y"]})
    return data, coords


def _observed(observed: Mapping | None, attrs: dict):
    import xarray as xr

    if not observed:
        return None
    if "images" in observed:  # a joint fit: image<k>, landmarks<k> with their own dimensions
        data, coords = {}, {}
        lms = observed.get("landmarks") or [None] * len(observed["images"])
        for k, (img, lm) in enumerate(zip(observed["images"], lms)):
            d, c = _observed_vars(img, lm, str(k))
            data.update(d)
            coords.update(c)
    else:
        data, coords = _observed_vars(observed.get("image"), observed.get("landmarks"))
    return xr.Dataset(data, coords=coords, attrs=attrs) if data else None


def inference_data(chains: Sequence[ChainResult], layout: ParamLayout | JointParamLayout,
                   template: RenderParameter | JointParameter,
                   model: MorphableModel | RegionAlbedo | None, *,
                   observed: Mapping | None = None, attrs: Mapping | None = None,
                   burn_fraction: float = 0.0):
    """Return the image stage of a fit's chains as an ``arviz.InferenceData``.

    Parameters
    ----------
    chains : sequence of ChainResult
        Chains without an image stage are left out; the others are cut to the
        shortest (in kept draws). When no chain ran the image stage, the landmark
        stage is stored instead (attribute ``stage``: "landmarks").
    layout : ParamLayout or JointParamLayout
        Columns of the samples. A joint fit's per-photograph blocks get an
        ``image`` dimension after ``draw`` (``pose`` (chain, draw, image,
        pose_param), ...); its shared ``shape`` and ``albedo`` do not.
    template : RenderParameter or JointParameter
        The fit's fixed fields (stored as ``template_rps``, or
        ``template_rps_images`` for a joint fit).
    model : MorphableModel or RegionAlbedo, optional
        For the derived ``albedo_mean`` (left out when None or without regions).
    observed : mapping, optional
        ``"image"``: (H, W, 3) float, the target as fitted; ``"landmarks"``:
        mapping name -> (2,) pixels. A joint fit: ``"images"`` and
        ``"landmarks"`` as lists, one per photograph (stored as ``image<k>``
        and ``landmarks<k>``).
    attrs : mapping, optional
        Provenance for every group: seed, model hash, software version, noise
        model, ... (values that are not str or numbers are stored as JSON).
    burn_fraction : float in [0, 1)
        For chains without a ``warmup`` record: the leading fraction of the kept
        draws that goes to the warm-up groups instead of the posterior.

    Returns
    -------
    arviz.InferenceData
        Groups as in the module notes (warm-up groups only when there are
        warm-up draws, ``observed_data`` only when given).
    """
    az = arviz()
    stage = "stage2" if any(c.stage2 is not None for c in chains) else "stage1"
    used = [c for c in chains if getattr(c, stage) is not None]
    basis = (model if isinstance(model, RegionAlbedo) or model is None
             else region_albedo_basis(model))
    coords = _coords(layout, basis)
    group_attrs = {**_attrs(attrs, template),
                   "stage": "image" if stage == "stage2" else "landmarks"}
    chain_ids = np.array([c.index for c in used], np.int64)
    groups = {}
    kept_recs = [getattr(c, stage) for c in used]
    n = min((r.samples.shape[0] for r in kept_recs), default=0)
    warm = [getattr(c, "warmup", None) if stage == "stage2" else None for c in used]
    have_warm = bool(used) and all(w is not None for w in warm)
    start = 0 if have_warm else int(burn_fraction * n)
    names = list(dict.fromkeys(p for r in [*kept_recs, *warm] if r is not None
                               for p in r.proposal_names))
    kept = (np.stack([r.samples[start:n] for r in kept_recs]) if used
            else np.zeros((0, 0, layout.size)))
    stats_attrs = {**group_attrs, "proposal_names": json.dumps(names)}
    groups["posterior"] = _dataset(_posterior_vars(kept, layout, basis), coords,
                                   np.arange(n - start), chain_ids, group_attrs)
    groups["sample_stats"] = _dataset(_stats_vars(kept_recs, start, n, names), {},
                                      np.arange(n - start), chain_ids, stats_attrs)
    if have_warm:
        w_n = min(w.samples.shape[0] for w in warm)
        w_recs, w_start = warm, 0
    else:
        w_n, w_recs, w_start = start, kept_recs, 0
    if w_n > 0:
        w_kept = np.stack([r.samples[w_start:w_n] for r in w_recs])
        groups["warmup_posterior"] = _dataset(_posterior_vars(w_kept, layout, basis), coords,
                                              np.arange(w_n), chain_ids, group_attrs)
        groups["warmup_sample_stats"] = _dataset(_stats_vars(w_recs, w_start, w_n, names), {},
                                                 np.arange(w_n), chain_ids, stats_attrs)
    obs = _observed(observed, group_attrs)
    if obs is not None:
        groups["observed_data"] = obs
    return az.InferenceData(**groups)


def write_posterior_nc(path: str | os.PathLike, idata) -> None:
    """Write ``idata`` to netCDF-4 (h5netcdf engine, compressed), atomically.

    Parameters
    ----------
    path : path-like
        The file (``posterior.nc`` in a result folder); read back with
        ``arviz.from_netcdf(path)``.
    idata : arviz.InferenceData
    """
    with atomic_path(path, suffix=".nc") as tmp:
        idata.to_netcdf(str(tmp), engine="h5netcdf")
