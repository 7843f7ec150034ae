"""The factors of the posterior: image, landmark and face-box likelihoods, priors, background.

Modules
-------
likelihoods
    The formulas: Gaussian pixels against a background, landmarks, face box.
background
    The colour-histogram background model.
image
    The target photograph for the image likelihood.
landmarks
    Target landmarks and their likelihood.
priors
    Priors over the fit parameters.
face
    :class:`~mcmcfit.targets.face.FaceTarget`: renderer + likelihoods + prior, the
    sampler's target.

The package imports only :mod:`albedo_model` (camera, errors, model, params,
render.raycast, render.renderer, shading.image_formation). This file imports nothing.
"""
