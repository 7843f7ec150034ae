"""Per-vertex textures from calibrated photographs: sampling, stitching, inpainting.

Modules
-------
cameras
    Calibrated cameras with lens distortion, and their JSON files.
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

Imports :mod:`albedo_model` only.
"""
