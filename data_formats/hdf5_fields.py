"""Checked reads from our HDF5 files (yarn curves, stitch meshes): root attributes, typed datasets, the format and
version check, and content sniffing. Every failure is a one-line ``FormatError`` naming the file and field."""

import re

import h5py
import numpy as np

from .errors import FormatError
from .input_files import HDF5_MAGIC, read_head

__all__ = ["HDF5_MAGIC", "check_format_attrs", "dataset", "sniff_hdf5", "str_attr", "string_dataset"]


def str_attr(f, name, where):
    if name not in f.attrs:
        raise FormatError(f"{where}: missing root attribute {name!r}")
    value = f.attrs[name]
    if isinstance(value, bytes):
        value = value.decode("utf-8", "replace")
    if not isinstance(value, str):
        raise FormatError(f"{where}: attribute {name}: got {value!r:.40}, expected a string")
    return value


def check_format_attrs(f, where, format_name, format_version):
    """Root ``format`` must be ``format_name``; ``version`` 'MAJOR.MINOR' with the reader's major (fail closed)."""
    fmt = str_attr(f, "format", where)
    if fmt != format_name:
        raise FormatError(f"{where}: attribute format = {fmt!r:.60}, expected {format_name!r}")
    version = str_attr(f, "version", where)
    match = re.fullmatch(r"(\d+)\.(\d+)", version)
    if not match:
        raise FormatError(f"{where}: attribute version = {version!r:.40}, expected 'MAJOR.MINOR' such as "
                          f"{format_version!r}")
    if match[1] != format_version.split(".")[0]:
        raise FormatError(f"{where}: unsupported {format_name} version {version}, this reader supports "
                          f"{format_version.split('.')[0]}.x")


def dataset(f, name, kinds, where):
    obj = f.get(name)
    if obj is None:
        raise FormatError(f"{where}: missing dataset {name!r}")
    if not isinstance(obj, h5py.Dataset) or obj.dtype.kind not in kinds:
        raise FormatError(f"{where}: {name}: got {getattr(obj, 'dtype', type(obj).__name__)}, "
                          f"expected a numeric dataset of kind {kinds!r}")
    return np.asarray(obj[()])


def string_dataset(f, name, where):
    obj = f.get(name)
    if obj is None:
        raise FormatError(f"{where}: missing dataset {name!r}")
    if not isinstance(obj, h5py.Dataset) or h5py.check_string_dtype(obj.dtype) is None or obj.ndim != 1:
        raise FormatError(f"{where}: {name}: got {getattr(obj, 'dtype', type(obj).__name__)} "
                          f"{getattr(obj, 'shape', '')}, expected a 1-D string dataset")
    return [str(s) for s in obj.asstr()[()]]


def sniff_hdf5(path, format_name) -> bool:
    """True if ``path`` is an HDF5 file whose root attribute ``format`` is ``format_name``; never raises."""
    if read_head(path, 8) != HDF5_MAGIC:
        return False
    try:
        with h5py.File(path, "r") as f:
            fmt = f.attrs.get("format")
        return (fmt.decode() if isinstance(fmt, bytes) else fmt) == format_name
    except Exception:
        return False
