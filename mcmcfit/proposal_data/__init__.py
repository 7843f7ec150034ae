"""What the data-driven proposals read from the accepted render state.

:mod:`~mcmcfit.proposal_data.albedo` linearises the render in the albedo
coefficients (the albedo conditional's system); :mod:`~mcmcfit.proposal_data.light_system`
linearises it in the SH light (the light conditional's normal equations);
:mod:`~mcmcfit.proposal_data.light` gathers normals, albedo and target colours
for the SH light solve. All are
functions of the proposal's explicit input (the accepted state and its render),
cached on the versions of the parameter blocks they read; they read the face
pixels of the render through :mod:`~mcmcfit.proposal_data.face_pixels`.

The package imports only :mod:`albedo_model` (camera, errors, params, render,
shading.effects) and :mod:`proposals` (albedo_solver, base, light_conditional). This file imports nothing.
"""
