"""The procedural template head: signed distance, mesh, landmarks, regions, shape model.

Imports :mod:`albedo_model` and :mod:`pipeline.modelling`.
"""
