"""Reports: plots, HTML pages, galleries."""
