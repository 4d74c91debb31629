"""Gather and scatter kernels; see _gather.pyx."""
