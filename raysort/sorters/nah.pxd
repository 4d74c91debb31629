"""The nah sorter; see nah.pyx."""
