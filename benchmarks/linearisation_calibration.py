"""Calibration of the albedo's linear-Gaussian conditional under noise in the encoded image.

A demo face (:func:`mcmcfit.jobs.synthetic_case.synthetic_case`) is rendered at
its true parameters; its encoded image gets Gaussian noise of sd ``--noise``
(the demo's 0.01) and 8-bit rounding, ``--draws`` times. With geometry, light
and everything but the albedo coefficients held at the truth, the render is
linear in the coefficients (its Jacobian by unit differences), so their
posterior under a Gaussian pixel likelihood and the N(0, I) prior is exact.
The 90 % intervals of the regions' mean diffuse albedo are scored against the
truth for three likelihoods:

* ``plain``: the linearised photograph ``x^2.2`` with one sigma for all pixels
  (the RMS residual) -- the fit before the sensor-noise correction;
* ``unbiased``: the photograph linearised for the noise
  (:func:`mcmcfit.targets.image.linearise` with ``sensor_sigma``) -- the fit now;
* ``unbiased, weighted``: as ``unbiased``, each pixel weighted by the inverse
  square of the encoding's slope at the noiseless render (noise constant in the
  encoded image) -- what a per-pixel noise model would add.

Prints, per face and likelihood, the coverage per channel (nominal 0.90), the
mean z of the regions' means (their bias in posterior sds) and the RMS z.

Usage: ``python benchmarks/linearisation_calibration.py [--faces 0 1 2] [--draws 300]``
(about a minute per face).
"""

from __future__ import annotations

import argparse

import numpy as np

from albedo_model.render.renderer import Renderer
from albedo_model.shading.image_formation import GAMMA
from mcmcfit.jobs.fit_job import load_model_cached
from mcmcfit.jobs.synthetic_case import synthetic_case
from mcmcfit.sampling.derived import region_albedo_basis
from mcmcfit.targets.image import linearise

KINDS = ("plain", "unbiased", "unbiased, weighted")


def _linear_problem(model, seed: int):
    """The render's pixels at the truth and their Jacobian in the albedo coefficients."""
    case = synthetic_case(model, seed=seed)
    truth = case.truth
    renderer = Renderer(model, specular=True, threads=1)

    def render(albedo):
        out = renderer.image(renderer.init_state(
            truth._replace(momo=truth.momo._replace(albedo=albedo))))
        return np.asarray(out.image, np.float64), out.mask

    a0 = np.asarray(truth.momo.albedo, np.float64)
    base, mask = render(a0)
    k = a0.size
    jac = np.stack([(render(a0 + np.eye(k)[j])[0] - base)[mask].ravel() for j in range(k)], 1)
    y0 = base[mask].ravel()
    inside = (y0 > 0.0) & (y0 < 1.0)
    return a0, jac[inside], y0[inside]


def score(model, seed: int, draws: int, noise: float) -> dict[str, np.ndarray]:
    """Return kind -> (draws, R*3) z-scores of the regions' mean albedo for one face."""
    a0, jac, y0 = _linear_problem(model, seed)
    regions = region_albedo_basis(model)
    k = a0.size
    basis = regions.basis.transpose(0, 2, 1).reshape(-1, k)
    truth = basis @ a0
    slope = GAMMA * np.maximum(y0 ** (1.0 / GAMMA), 1.0 / 255.0) ** (GAMMA - 1.0)
    rng = np.random.default_rng(seed)
    z = {kind: [] for kind in KINDS}
    for _ in range(draws):
        encoded = np.clip(y0 ** (1.0 / GAMMA) + rng.normal(0.0, noise, y0.shape), 0.0, 1.0)
        encoded = np.round(encoded * 255.0) / 255.0
        for kind in KINDS:
            y = linearise(encoded, 0.0 if kind == "plain" else noise)
            w = 1.0 / slope ** 2 if kind.endswith("weighted") else np.ones_like(y)
            normal = jac.T @ (w[:, None] * jac)
            rhs = jac.T @ (w * (y - y0))
            resid = y - y0 - jac @ np.linalg.solve(normal, rhs)
            s2 = np.sum(w * resid ** 2) / y.size
            cov = np.linalg.inv(normal / s2 + np.eye(k))
            mean = a0 + cov @ (rhs / s2 - a0)
            sd = np.sqrt(np.einsum("ik,kl,il->i", basis, cov, basis))
            z[kind].append((basis @ mean - truth) / sd)
    return {kind: np.asarray(v) for kind, v in z.items()}


def main(argv: list[str] | None = None) -> None:
    """Print coverage and bias of the regions' mean albedo for each face and likelihood."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--faces", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--draws", type=int, default=300)
    ap.add_argument("--noise", type=float, default=0.01)
    args = ap.parse_args(argv)
    model = load_model_cached("default", progress=False).model
    for seed in args.faces:
        for kind, z in score(model, seed, args.draws, args.noise).items():
            cover = (np.abs(z) < 1.645).mean(axis=0).reshape(-1, 3).mean(axis=0)
            print(f"face {seed} {kind:>19}: 90 % coverage r,g,b {np.round(cover, 3)}, "
                  f"mean z {np.round(z.mean(axis=0).reshape(-1, 3).mean(axis=0), 2)}, "
                  f"RMS z {np.sqrt(np.mean(z ** 2)):.2f}")


if __name__ == "__main__":
    main()
