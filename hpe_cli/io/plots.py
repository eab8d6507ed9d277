"""Moved to :mod:`hpe_cli.report.plots`; this name stays importable until every caller uses the new one."""
from ..report.plots import *  # noqa: F403
from ..report import plots as _m

globals().update({k: getattr(_m, k) for k in dir(_m) if not k.startswith("__")})
