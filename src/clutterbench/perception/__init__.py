"""Perception: object masks from an observation (instance image or depth segmentation)."""
