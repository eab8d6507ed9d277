"""The ``hpe`` command group. Subcommands are imported only when used, so ``hpe --help`` stays fast."""
from __future__ import annotations

import importlib
import importlib.util
import os

import click

from .. import __version__

#: command name -> "module:function". One module per command.
COMMANDS = {
    "convert": "hpe_cli.cli.convert:convert",
    "systems": "hpe_cli.cli.systems:systems",
    "relabel-panoptic": "hpe_cli.cli.relabel_panoptic:relabel_panoptic",
    "relabel-agora": "hpe_cli.cli.relabel_agora:relabel_agora",
    "audit": "hpe_cli.cli.audit:audit",
    "draw": "hpe_cli.cli.draw:draw",
    "augment": "hpe_cli.cli.augment:augment",
    "infer": "hpe_cli.cli.infer:infer",
    "export": "hpe_cli.cli.export:export",
}


class HpeGroup(click.Group):
    """Lazy subcommands; failures become one line on stderr and exit code 1."""

    def list_commands(self, ctx):
        return [n for n, target in COMMANDS.items() if importlib.util.find_spec(target.split(":")[0])]

    def get_command(self, ctx, name):
        target = COMMANDS.get(name)
        if target is None:
            return None
        module, attr = target.split(":")
        if importlib.util.find_spec(module) is None:
            return None
        return getattr(importlib.import_module(module), attr)

    def invoke(self, ctx):
        from ..errors import HpeError
        from ..rotation.systems import SystemError_

        try:
            return super().invoke(ctx)
        except (click.exceptions.Exit, click.exceptions.Abort, click.ClickException):
            raise
        except (HpeError, SystemError_) as exc:
            click.echo(f"Error: {exc}", err=True)
            ctx.exit(1)
        except BrokenPipeError:  # e.g. `hpe systems | head`: the reader left, nothing to report
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, 1)
            ctx.exit(1)
        except KeyboardInterrupt:
            click.echo("Error: interrupted", err=True)
            ctx.exit(130)
        except Exception as exc:  # never show a traceback unless asked to
            if os.environ.get("HPE_DEBUG"):
                raise
            click.echo(f"Error: unexpected {type(exc).__name__}: {' '.join(str(exc).split())[:300]} "
                       "(set HPE_DEBUG=1 for a traceback)", err=True)
            ctx.exit(1)


@click.group(cls=HpeGroup, context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(__version__, prog_name="hpe")
def cli():
    """hpe: relabel head-pose datasets correctly.

    Every label has a rotation system (frame, axes and handedness, range,
    order). hpe converts between systems exactly, relabels Panoptic and AGORA
    from 3-D landmarks, audits, draws and augments labels, and infers the
    system a piece of code or data uses.

    \b
    Examples:
      hpe systems
      hpe convert labels.csv -o labels_6d.parquet --from 300w_lp --to 6drepnet
      hpe convert AFLW2000/ -o aflw.parquet --from 300w_lp --to whenet
      hpe relabel-panoptic sample_data/panoptic -o labels.parquet
      hpe audit labels.parquet --system 300w_lp --json report.json
    """
