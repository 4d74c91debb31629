# cython: language_level=3
"""Gather and scatter kernels; see _gather.pyx."""
