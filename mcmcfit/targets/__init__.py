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
noise_model
    The image likelihood's scale per image: RMS residual and correlation area.
face
    :class:`~mcmcfit.targets.face.FaceTarget`: renderer + likelihoods + prior, the
    sampler's target.
joint
    :class:`~mcmcfit.targets.joint.JointTarget`: several photographs of one face (one
    face target per image, the identity's prior once).
gradient
    The posterior's gradient in shape, expression, pose and camera (gradient moves).
curvature
    The posterior's gradient and Gauss-Newton precision in every continuous parameter
    over a fixed pixel region (the climb to the mode, the Laplace approximation, HMC).

The package imports :mod:`albedo_model` (camera, errors, model, params, scene_vector,
render.differentiable, render.jacobian, render.pixel_cast, render.renderer,
shading.image_formation) and :mod:`proposals` (gradient, joint). This file imports nothing.
"""
