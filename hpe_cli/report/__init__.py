"""Reports: plots, HTML pages and picture galleries built from what the pipelines computed.

``plots`` (``hpe audit --plots``, with the drawn flagged rows that
:func:`hpe_cli.pipelines.draw.flagged_pictures` passes in), ``eval_plots`` (``hpe evaluate --plots``).
Drawings of single rows (ground truth against prediction) come from :func:`hpe_cli.pipelines.draw.draw_worst`.
Nothing here imports the pipelines: the pictures are handed to the page builders.
"""
