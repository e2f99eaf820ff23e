"""``knitrun``: the runtime's command line. Thin: parse, call ``data_formats``/``knitrun``, report."""

from __future__ import annotations

from pathlib import Path

import click

from cli.common import FriendlyGroup, file_kind
from data_formats import FormatError

CONTEXT = {"help_option_names": ["-h", "--help"], "max_content_width": 110}


@click.group(name="knitrun", cls=FriendlyGroup, context_settings=CONTEXT)
@click.version_option(package_name="knit", prog_name="knitrun")
def main():
    """Runtime of knit: yarn curves and asset packs in, images out.

    \b
    Examples:
      knitrun convert yarns.h5 yarns.bcc
    """


@main.command()
@click.argument("source", type=click.Path(dir_okay=False))
@click.argument("target", type=click.Path(dir_okay=False))
@click.option("--frame", type=click.IntRange(min=0), default=0, show_default=True,
              help="Frame to write when the target is BCC (one frame per file).")
@click.option("--units", default="cm", show_default=True, help="Units to record when the source is BCC (it has none).")
def convert(source, target, frame, units):
    """Convert yarn curves between our HDF5 file and BCC (by the target's extension).

    Example: knitrun convert cotton1.bcc cotton1.h5 --units cm
    """
    from data_formats.bcc import read_bcc, write_bcc
    from data_formats.yarn_curves import read_yarn_curves, write_yarn_curves

    kind, _ = file_kind(source)
    if kind == "bcc":
        curves = read_bcc(source, units=units)
    elif kind == "yarn-curves":
        curves = read_yarn_curves(source)
    else:
        raise FormatError(f"{source}: is a {kind}, not yarn curves")
    suffix = Path(target).suffix.lower()
    if suffix == ".bcc":
        if frame >= curves.points.shape[0]:
            raise FormatError(f"--frame {frame}: {source} has {curves.points.shape[0]} frame(s)")
        write_bcc(target, curves, frame=frame)
    elif suffix in (".h5", ".hdf5"):
        write_yarn_curves(target, curves)
    else:
        raise FormatError(f"{target}: target must end in .bcc, .h5 or .hdf5")
    click.echo(f"{source} ({kind}, {len(curves.closed)} curves) → {target}")
