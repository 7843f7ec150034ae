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

Imports :mod:`albedo_model`, :mod:`proposals` and :mod:`mcmcfit.sampling`.
"""
