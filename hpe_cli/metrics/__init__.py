"""Evaluation metrics and published protocols (pure numpy)."""
