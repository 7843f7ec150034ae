"""Lightstage processing: capture folder in, albedo model out (``mcmcfit pipeline build``).

Modules
-------
capture_folder, spectral_csv
    What ``pipeline build`` reads: the capture folder layout, spectra (meshes and
    photographs are read by :mod:`pipeline.texturing.capture_io`).
colour
    Camera spectral model and the calibrated colour transform RAW -> linear sRGB.
polarisation
    Polarised diffuse/specular separation.
dome_shading, camera_render
    Irradiance and specular lobe in the LED dome; ray-cast images seen by a camera.
processing
    One subject: polarised images -> stitched diffuse and specular albedo.
external_scans
    Integrating external single-view scans.
assembly, build
    The population stage (completion, modelling, evaluation) and the whole build.

This file imports nothing; its modules import :mod:`albedo_model`, :mod:`pipeline.texturing`
and :mod:`pipeline.modelling`.
"""
