"""Per-vertex textures from calibrated photographs: sampling, stitching, inpainting.

Modules
-------
cameras
    Calibrated cameras with lens distortion, and their JSON files.
capture_io, json_files
    Reading registered meshes and view photographs; reading JSON files of a capture.
triangle_coverage
    Which pixel centres projected triangles cover.
view_sampling
    Per-view sampling of photographs onto a registered mesh.
poisson_stitching
    Screened-Poisson stitching of per-view colours.
stitch_capture
    ``mcmcfit pipeline stitch``: files in, per-vertex texture out.
inpainting
    Statistical inpainting with Poisson blending.
texture_preview
    Photographs beside renders of a stitched texture.

This file imports nothing; its modules import :mod:`albedo_model` and one another.
"""
