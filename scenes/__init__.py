"""Scenes that ship with raysort (meshes, cameras, materials)."""
