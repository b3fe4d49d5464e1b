"""Applications: video render, live viewer, timeline figure."""
