"""Lightstage processing and the synthetic lightstage. Imports only albedo_model."""
