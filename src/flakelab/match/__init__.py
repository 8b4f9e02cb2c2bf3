"""Formulation matching and correction: the main job."""
