"""Root pytest configuration: collect hpe_cli/torch (doctests) only when the optional torch extra is installed."""

import importlib.util

collect_ignore_glob = []
if importlib.util.find_spec("torch") is None or importlib.util.find_spec("torchvision") is None:
    collect_ignore_glob.append("hpe_cli/torch/*")
