# cython: language_level=3
"""The nah sorter; see nah.pyx."""
