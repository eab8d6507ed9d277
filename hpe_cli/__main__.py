"""``python -m hpe_cli``: the ``hpe`` command."""

from hpe_cli.cli.main import main

if __name__ == "__main__":
    main()
