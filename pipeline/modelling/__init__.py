"""Statistical modelling of albedo: PCA variants, symmetry augmentation, generalisation.

Modules
-------
pca_variants
    The paper's three diffuse/specular PCA variants (independent, concatenated, transferred).
symmetry
    Mirroring per-vertex fields across the face's plane of symmetry.
generalisation
    Leave-one-out generalisation of the specular variants (and the Gram-space folds).
residual_variance
    Leave-one-out per-vertex residual variance of the albedo PCA (what it cannot represent).

This file imports nothing; its modules import only :mod:`albedo_model` (and each other).
"""
