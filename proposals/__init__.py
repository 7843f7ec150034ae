"""Metropolis-Hastings proposals over fit parameters. Imports only albedo_model."""
