"""Built-in sorters."""
