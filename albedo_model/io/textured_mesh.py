"""Write a textured triangle mesh as OBJ + MTL and as binary glTF (through trimesh).

The mesh is split at the UV atlas's seams (one vertex per texture point), as
both formats need. The diffuse texture is the material's colour map: OBJ's
``map_Kd`` and glTF's ``baseColorTexture`` (an 8-bit sRGB-encoded image, which
is what both expect; Blender reads it as sRGB). A specular texture, when given,
is the OBJ material's ``map_Ks``; glTF 2.0's core material has no specular
colour, so the ``.glb`` carries the diffuse texture only (metallic 0).

Files are written atomically; the ``.glb`` embeds its texture, the ``.obj``
names ``<stem>.mtl``, which names the texture files by their names (keep them
in one folder).

This module imports :mod:`albedo_model.errors`, :mod:`albedo_model.uv_atlas` and
:mod:`albedo_model.io.atomic` (and trimesh, Pillow).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from albedo_model.errors import InputError
from albedo_model.io.atomic import atomic_path
from albedo_model.uv_atlas import UVAtlas, uv_vertices

__all__ = ["write_textured_mesh"]


def _image(pixels: np.ndarray):
    from PIL import Image

    px = np.asarray(pixels)
    if px.dtype != np.uint8 or px.ndim != 3 or px.shape[2] != 3:
        raise InputError(f"textures must be 8-bit RGB (H, W, 3), got {px.dtype} {px.shape}")
    return Image.fromarray(px, "RGB")


def write_textured_mesh(folder: str | os.PathLike, stem: str, vertices: np.ndarray,
                        triangles: np.ndarray, atlas: UVAtlas, diffuse_png: str,
                        diffuse: np.ndarray, specular_png: str | None = None) -> list[Path]:
    """Write ``<stem>.obj``, ``<stem>.mtl`` and ``<stem>.glb`` into ``folder``.

    Parameters
    ----------
    folder : path-like
        An existing folder; the texture PNGs are expected there under the names given.
    stem : str
        File name without suffix.
    vertices : (n, 3) float array
        The mesh (model frame, mm).
    triangles : (m, 3) int array
    atlas : UVAtlas
        Texture coordinates of ``triangles`` (the baked texture's snapped atlas).
    diffuse_png : str
        File name of the 8-bit sRGB diffuse texture (``map_Kd``).
    diffuse : (H, W, 3) uint8 array
        Its pixels (embedded in the ``.glb``).
    specular_png : str, optional
        File name of the 8-bit sRGB specular texture (``map_Ks``).

    Returns
    -------
    list of Path
        The files written.
    """
    import trimesh
    from trimesh.exchange.obj import export_obj

    v = np.asarray(vertices, np.float64)
    tri = np.asarray(triangles)
    atlas.check_mesh(tri, len(v))
    if not Path(diffuse_png).stem or Path(diffuse_png).suffix.lower() != ".png":
        raise InputError(f"the diffuse texture must be a .png file name, got {diffuse_png!r}")
    out = Path(folder)
    owner = np.maximum(uv_vertices(atlas, tri), 0)
    image = _image(diffuse)
    written = []

    # trimesh names the MTL's map after the material: name it after the texture file
    simple = trimesh.visual.material.SimpleMaterial(
        image=image, name=Path(diffuse_png).stem, diffuse=(255, 255, 255, 255),
        ambient=(0, 0, 0, 255), specular=(255, 255, 255, 255) if specular_png else (0, 0, 0, 255))
    mesh = trimesh.Trimesh(v[owner], atlas.uv_triangles, process=False,
                           visual=trimesh.visual.TextureVisuals(uv=atlas.uv, material=simple))
    obj_text, files = export_obj(mesh, include_normals=True, include_texture=True,
                                 return_texture=True, mtl_name=f"{stem}.mtl")
    mtl = files[f"{stem}.mtl"].decode()
    if f"map_Kd {diffuse_png}" not in mtl:
        raise InputError(f"trimesh wrote an MTL without 'map_Kd {diffuse_png}'")
    if specular_png:
        mtl = mtl.rstrip("\n") + f"\nmap_Ks {specular_png}\n"
    for name, text in ((f"{stem}.obj", obj_text), (f"{stem}.mtl", mtl)):
        with atomic_path(out / name) as tmp:
            Path(tmp).write_text(text, encoding="utf-8")
        written.append(out / name)

    pbr = trimesh.visual.material.PBRMaterial(name=Path(diffuse_png).stem, baseColorTexture=image,
                                              metallicFactor=0.0, roughnessFactor=0.6)
    mesh.visual = trimesh.visual.TextureVisuals(uv=atlas.uv, material=pbr)
    with atomic_path(out / f"{stem}.glb") as tmp:
        Path(tmp).write_bytes(trimesh.exchange.gltf.export_glb(mesh))
    written.append(out / f"{stem}.glb")
    return written
