"""Input/output of models, parameters, landmarks and meshes (one module per format).

Modules
-------
model_files
    Finding, recognising, loading and combining model files.
momo_h5, hdf5_layout
    Morphable models in HDF5 (scalismo MoMo, AlbedoMM joint models, albedo
    parts) and the low-level pieces of that layout.
flame_npz
    AlbedoMM's FLAME albedo model (``.npz``).
rps, rps_blocks, rps_legacy, json_fields
    ``.rps`` render-parameter JSON (read V1-V4, write V4), its blocks, the
    historic versions, and typed access to JSON fields.
tlms, pts
    Landmark files: scalismo-faces TLMS and iBUG 68-point ``.pts``.
image_io
    Reading and writing PNG/JPEG images.
colour_space
    A model's colour space (linear albedo or gamma-encoded sRGB texture) and
    the sRGB decoding and encoding of texture values.
mesh_export
    Meshes with per-vertex colours to PLY or OBJ.
atomic, text_files
    Atomic file writing; reading small UTF-8 text files.

The package imports :mod:`albedo_model` (default_model, errors, model, params, pca)
only. This file imports nothing.
"""
