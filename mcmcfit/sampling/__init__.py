"""The MCMC core: the Metropolis filter-chain kernel, chain records and convergence diagnostics.

Modules
-------
kernel
    One Metropolis-Hastings step as proposal -> landmark filter -> prior filter
    -> image step (:func:`~mcmcfit.sampling.kernel.step`, :func:`~mcmcfit.sampling.kernel.run`).
chain
    Per-step logs, thinned samples and the chain HDF5 file.
param_vector
    Flat vectors of the sampled parameters (the columns of ``chain.h5``).
diagnostics
    Rank-normalised split R-hat, bulk- and tail-ESS (ArviZ's estimators, vectorised).
convergence
    The convergence verdict and the monitored quantities.
derived
    Derived monitored quantities: the regions' mean diffuse albedo per draw.

The package imports only :mod:`albedo_model` (errors, model, params, regions,
io.atomic, io.rps, render.cache_table) and :mod:`proposals.base`. This file imports
nothing.
"""
