"""Statistical modelling of albedo: PCA variants, symmetry augmentation, generalisation.

Modules
-------
pca_variants
    The paper's three diffuse/specular PCA variants (independent, concatenated, transferred).
symmetry
    Mirroring per-vertex fields across the face's plane of symmetry.
generalisation
    Leave-one-out generalisation of the specular variants.

Imports :mod:`albedo_model` only.
"""
