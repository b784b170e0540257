"""The pipeline coordinator: state machine core, node, results and trial runner."""
