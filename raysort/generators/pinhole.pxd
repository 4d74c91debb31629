"""The pinhole generator; see pinhole.pyx."""
