"""``python -m hpe_cli``: the ``hpe`` command."""
from hpe_cli.cli.main import cli

if __name__ == "__main__":
    cli(prog_name="hpe")
