"""Learned forward model: an MLP from toner amounts to multi-angle reflectance and texture."""
