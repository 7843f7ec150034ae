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
    Autocorrelation time, ESS and split R-hat.

The package imports only :mod:`albedo_model` (errors, params, io.atomic, io.rps,
render.cache_table) and :mod:`proposals.base`. This file imports nothing.
"""
