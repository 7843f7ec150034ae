"""One fit of a face image, in the order of its data flow.

Modules
-------
config
    :class:`~mcmcfit.fitting.config.FitConfig`, the settings of a fit.
initialisation
    Starting parameters: the camera for the image size and a pose guess.
landmark_stage_emcee
    The alternative emcee landmark stage.
fit
    :func:`~mcmcfit.fitting.fit.fit`: landmark stage, then image stage, per chain.
result
    :class:`~mcmcfit.fitting.result.FitResult`: chains, best and mean parameters, diagnostics.
progress
    The progress bar.
cache_check
    ``--check-cache``: every cached product of a chain against a fresh computation.

The package imports :mod:`albedo_model`, :mod:`proposals` (base, light_solver, schedule),
:mod:`mcmcfit.sampling`, :mod:`mcmcfit.targets` and :mod:`mcmcfit.proposal_data`.
This file imports nothing.
"""
