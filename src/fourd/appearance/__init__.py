"""Colour and video: what the scans' appearance gives the result."""

from fourd.appearance.vertex_colors import vertex_colors

__all__ = ["vertex_colors"]
