"""raysort: ray sorting for fast incoherent packet ray tracing."""
