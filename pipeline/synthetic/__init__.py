"""The synthetic lightstage: subjects with ground truth, simulated captures, the default model.

Modules
-------
skin_spectral, subjects
    Spectral skin reflectance and synthetic subjects with ground-truth albedo.
dome, capture, write_captures
    The LED dome and cameras, the capture simulator, and the capture folder it writes.
albedo_preview
    Rendered views of per-vertex albedo maps.
default_model
    The built-in default model: synthetic population -> AlbedoMM HDF5, cached.
face_region, default_face_model
    The face region of the template head, and ``default-face``: the default model cropped
    to it (cached beside it).
head
    The procedural template head and its shape model.

This file imports nothing; its modules import :mod:`albedo_model`, :mod:`pipeline.lightstage`,
:mod:`pipeline.texturing` and :mod:`pipeline.modelling`.
"""
