# cython: language_level=3
"""Brute-force reference kernel; see _reference.pyx."""
