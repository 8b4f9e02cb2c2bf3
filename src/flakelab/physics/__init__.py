"""Coating optics: formulation → spectral BRDF (fast model, scaling form, Monte Carlo)."""
