"""A Foxglove live bridge for the running graph (``live_view``)."""
