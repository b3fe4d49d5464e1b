"""Metrics: physical plausibility and motion quality."""
