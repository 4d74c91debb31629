"""Brute-force reference kernel; see _reference.pyx."""
