"""CPU feature detection; see _cpu.pyx."""
