"""Render layer: images and plots of appearance."""

from flakelab.render.plots import plot_measurements, plot_rendering, plot_side_by_side

__all__ = ["plot_measurements", "plot_rendering", "plot_side_by_side"]
