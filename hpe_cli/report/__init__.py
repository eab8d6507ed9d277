"""Reports: plots, HTML pages and picture galleries built from what the pipelines computed.

``plots`` (``hpe audit --plots``), ``eval_plots`` (``hpe evaluate --plots``). Drawings of single rows (ground
truth against prediction) come from :func:`hpe_cli.pipelines.draw.draw_worst`.
"""
