"""The lambert shader; see lambert.pyx."""
