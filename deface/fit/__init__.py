"""Fitting: configs and presets, the three stages, and the pipeline that composes them."""
