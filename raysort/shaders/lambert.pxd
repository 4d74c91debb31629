# cython: language_level=3
"""The lambert shader; see lambert.pyx."""
