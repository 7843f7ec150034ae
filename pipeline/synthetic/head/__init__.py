"""The procedural template head: signed distance, mesh, landmarks, regions, shape model.

Modules
-------
head_sdf
    Signed-distance description of the head and its facial features.
landmarks, regions
    Basel landmark names on the template's vertices; region masks (albedo, specular).
template_head
    The template mesh, meshed from the signed distance
    (:class:`~pipeline.synthetic.head.template_head.TemplateHead`).
shape_model
    Shape and expression variation on the template head, as PCA parts.

This file imports nothing; its modules import only :mod:`albedo_model` (``errors``, ``pca``)
and each other.
"""
