"""Camera-based perception. Vision sorting for the pipeline cell is planned (issue 5)."""
