"""Moves from a Laplace approximation of the posterior: its coordinates, the moves, their schedule.

Modules: ``coordinates`` (the sampled scene entries, positive ones on a log
scale, and the Jacobian of the map to the parameters), ``moves`` (the
Gaussian approximation; Crank-Nicolson, Gaussian block conditionals and
whitened HMC moves on it), ``schedule`` (the Gaussian sampler's image-stage
mixture with the exact albedo and SH-light conditionals).

The subpackage sits above the root modules of :mod:`proposals` and imports
them (base, gradient, albedo_solver, light_conditional, schedule) and
:mod:`albedo_model` (errors, params, scene_vector). This file imports nothing.
"""
