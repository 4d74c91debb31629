# cython: language_level=3
"""The pinhole generator; see pinhole.pyx."""
