"""Shared CLI plumbing: one-line errors instead of tracebacks, JSON output, and the file-kind registry.

A user mistake (bad file, bad value, missing file) prints ``<prog>: error: <one line>`` on stderr and exits 1;
click's own usage errors exit 2. Set ``KNIT_DEBUG=1`` to see the traceback instead.
"""

from __future__ import annotations

import json
import os
import sys
import traceback
from types import SimpleNamespace

import click

from data_formats import (FormatError, asset_pack, bcc, curves_dcc, engine_export, scene, smobj, stitch_mesh,
                          yarn_curves, yarn_spec)
from data_formats.input_files import HDF5_MAGIC, read_head, regular_file
from data_formats.jsonable import jsonable
from knitrun.sim import knitout

# An OBJ stitch mesh (+ its .labels sidecar) through the same three calls as the other kinds.
_STITCH_MESH_OBJ = SimpleNamespace(sniff=stitch_mesh.sniff_obj, describe=stitch_mesh.describe_obj,
                                   validate=stitch_mesh.validate_obj)
# OBJ polylines as yarn curves (a mesh OBJ has faces; polylines have none)
_CURVES_OBJ = SimpleNamespace(sniff=curves_dcc.sniff_obj_curves, describe=curves_dcc.describe_obj_curves,
                              validate=curves_dcc.validate_obj_curves)
# Recognised by content, most specific first: (kind, module with sniff/describe/validate).
FILE_KINDS = (("asset-pack", asset_pack), ("yarn-curves", yarn_curves), ("stitch-mesh", stitch_mesh), ("bcc", bcc),
              ("scene", scene), ("yarn-spec", yarn_spec), ("stitch-mesh-smobj", smobj),
              ("knitout", knitout), ("yarn-curves-obj", _CURVES_OBJ), ("stitch-mesh-obj", _STITCH_MESH_OBJ),
              ("engine-export", engine_export))
# a user's mistake (bad file, field, argument; a file system refusing) is one line; any other exception is a bug of
# ours and shows its traceback
USER_ERRORS = (FormatError, OSError)
SEED = click.IntRange(0, 2**63 - 1)  # every --seed: what numpy's and Numba's generators take (int64, non-negative)
CONTEXT = {"help_option_names": ["-h", "--help"], "max_content_width": 110}  # both programs' click settings


class SuffixPath(click.Path):
    """A file path whose name must end in one of ``suffixes`` (case-insensitive), e.g. ``SuffixPath(".h5", ".hdf5")``
    for an asset pack. A wrong suffix is a one-line user error (exit 1) naming the path and the option."""

    def __init__(self, *suffixes: str):
        super().__init__(dir_okay=False)
        self.suffixes = tuple(s.lower() for s in suffixes)

    def convert(self, value, param, ctx):
        value = super().convert(value, param, ctx)
        if not str(value).lower().endswith(self.suffixes):
            label = param.opts[-1] if isinstance(param, click.Option) else param.name
            choices = ", ".join(self.suffixes[:-1]) + (" or " if len(self.suffixes) > 1 else "") + self.suffixes[-1]
            raise FormatError(f"{value}: {label} must end in {choices}")
        return value


class FriendlyGroup(click.Group):
    """A click group whose commands report user errors in one line on stderr."""

    def invoke(self, ctx):
        prog = ctx.find_root().info_name
        try:
            return super().invoke(ctx)
        except BrokenPipeError:  # output piped into e.g. `head`: stop quietly
            sys.stdout = open(os.devnull, "w")
            sys.exit(0)
        except USER_ERRORS as exc:
            if os.environ.get("KNIT_DEBUG"):
                raise
            message = " ".join(str(exc).split()) or exc.__class__.__name__
            click.echo(f"{prog}: error: {message}", err=True)
            sys.exit(1)
        except KeyboardInterrupt:
            click.echo(f"{prog}: interrupted", err=True)
            sys.exit(130)
        except (click.exceptions.ClickException, click.exceptions.Exit, click.exceptions.Abort, SystemExit):
            raise
        except Exception as exc:  # noqa: BLE001  (not a user error: a bug, reported as one)
            traceback.print_exc()
            click.echo(f"{prog}: internal error (a bug of {prog}, not of your input; please report it with the "
                       f"traceback above): {exc.__class__.__name__}: {' '.join(str(exc).split())}", err=True)
            sys.exit(70)  # EX_SOFTWARE


def check_outputs(outputs: dict, inputs=()) -> None:
    """Before any work: every output's folder exists, no output is one of the ``inputs`` (it would be overwritten
    while the command still reads it, or replace the user's data), and no two outputs are the same file.
    ``outputs``: option label → path (None: not asked for). One-line ``FormatError`` otherwise."""
    seen = {}
    for label, path in outputs.items():
        if path is None:
            continue
        folder = os.path.dirname(os.path.abspath(path))
        if not os.path.isdir(folder):
            raise FormatError(f"{path}: output folder {os.path.dirname(path) or '.'} does not exist ({label})")
        for source in inputs:
            if source is not None and _same_file(path, source):
                raise FormatError(f"{path}: is both an input and an output ({label}); it would be overwritten")
        for other, other_path in seen.items():
            if _same_file(path, other_path):
                raise FormatError(f"{path}: given as two outputs ({other} and {label})")
        seen[label] = path


def _same_file(a, b) -> bool:
    if os.path.exists(a) and os.path.exists(b):
        return os.path.samefile(a, b)
    return os.path.realpath(a) == os.path.realpath(b)


def file_kind(path):
    """(kind, module) of a file the toolchain reads, recognised by its content; FormatError if none."""
    regular_file(path, "a file the toolchain reads")
    for kind, module in FILE_KINDS:
        if module.sniff(path):
            return kind, module
    if read_head(path, 8) == HDF5_MAGIC:
        raise FormatError(f"{path}: an HDF5 file that cannot be opened or is none of ours (truncated or corrupt?)")
    raise FormatError(f"{path}: not a file the toolchain reads (asset pack, yarn curves HDF5, BCC or OBJ polylines, "
                      f"stitch mesh HDF5, OBJ or .smobj, knitout, scene or yarn spec TOML, engine-export manifest)")


def echo_json(obj):
    click.echo(json.dumps(jsonable(obj), indent=2, allow_nan=False))


def echo_tree(obj, indent=0):
    """Human-readable nested dict/list printing (one 'key: value' per line)."""
    pad = "  " * indent
    for key, value in obj.items():
        if isinstance(value, dict) and value:
            click.echo(f"{pad}{key}:")
            echo_tree(value, indent + 1)
        elif isinstance(value, list) and value and isinstance(value[0], dict):
            click.echo(f"{pad}{key}:")
            for i, item in enumerate(value):
                click.echo(f"{pad}  [{i}]")
                echo_tree(item, indent + 2)
        else:
            click.echo(f"{pad}{key}: {_fmt(value)}")


def _fmt(value):
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_fmt(v) for v in value) + "]"
    return str(value)
