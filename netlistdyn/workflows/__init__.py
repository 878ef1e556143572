"""Pipelines over many cases: sweeps, superposition, large circuits."""
