"""hpe: relabel head-pose datasets correctly."""
__version__ = "0.1.0"
