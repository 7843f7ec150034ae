"""One fit of a face image, in the order of its data flow.

Modules
-------
config
    :class:`~mcmcfit.fitting.config.FitConfig`, the settings of a fit.
initialisation
    Starting parameters: the camera for the image size and a pose guess.
problem
    :class:`~mcmcfit.fitting.problem.FitProblem`, what the chains share, and each
    chain's targets under a noise model.
landmark_starts
    The landmark stage from several starts, the best continued.
landmark_stage_emcee
    The alternative emcee landmark stage.
adaptation
    Warm-up adaptation of step sizes and the gradient moves' preconditioner.
mode
    The climb to the posterior mode (Levenberg-Marquardt) and the Laplace approximation.
gaussian_stage
    The Gaussian sampler's preparation of a chain: climb, region and noise, Laplace.
chain_session
    One chain run in phases: landmarks, preparation, warm-up, kept draws.
chain_pool, chain_worker
    The chains in this process or in parallel worker processes.
fit
    :func:`~mcmcfit.fitting.fit.fit`: the phases of all chains in lockstep, the stop rule.
result
    :class:`~mcmcfit.fitting.result.FitResult`: chains, best and mean parameters, diagnostics.
progress
    The progress bar.
cache_check
    ``--check-cache``: every cached product of a chain against a fresh computation.

The package imports :mod:`albedo_model`, :mod:`proposals` (base, light_solver, schedule,
laplace),
:mod:`mcmcfit.sampling`, :mod:`mcmcfit.targets` and :mod:`mcmcfit.proposal_data`.
This file imports nothing.
"""
