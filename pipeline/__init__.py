"""Lightstage processing and the synthetic lightstage.

Subpackages
-----------
lightstage
    Lightstage processing: capture folder in, albedo model out (``mcmcfit pipeline build``).
texturing
    Per-vertex textures from calibrated photographs: sampling, stitching, inpainting.
modelling
    Statistical modelling of albedo: PCA variants, symmetry augmentation, generalisation.
synthetic
    The synthetic lightstage: subjects with ground truth, simulated captures, the default model.

This file imports nothing; outside :mod:`pipeline` its modules import only :mod:`albedo_model`.
"""
