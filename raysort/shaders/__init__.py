"""Built-in shaders."""
