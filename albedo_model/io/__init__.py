"""Input/output of models, parameters, landmarks and meshes (one module per format)."""
