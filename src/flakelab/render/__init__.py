"""Render layer: images and plots of appearance."""

from flakelab.render.plots import plot_measurements

__all__ = ["plot_measurements"]
