# cython: language_level=3
"""CPU feature detection; see _cpu.pyx."""
