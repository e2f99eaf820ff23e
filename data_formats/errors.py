"""The one error type every reader, writer and validator in ``data_formats`` raises for bad input.

A ``FormatError`` message is a single line that names the file or field, the bad value, and what was expected, so
the CLI can print it as is (``knitbake: error: <message>``) without a traceback.
"""


class FormatError(ValueError):
    """Malformed, corrupt or out-of-range input; the message is one line naming what is wrong."""


def one_line(e) -> str:
    """The message of exception ``e`` with its whitespace (newlines included) collapsed to single spaces."""
    return " ".join(str(e).split())


def read_problems(read, *args, any_error: bool = False) -> list[str]:
    """The ``validate`` of a reader: [] when ``read(*args)`` succeeds, else its one-line ``FormatError``. With
    ``any_error`` (HDF5 readers, whose corrupt internals surface as assorted h5py errors) any other exception is a
    problem too, named as the first argument being unreadable; otherwise it propagates (a bug, not bad input)."""
    try:
        read(*args)
    except FormatError as e:
        return [str(e)]
    except Exception as e:
        if not any_error:
            raise
        return [f"{args[0]}: unreadable ({type(e).__name__}: {one_line(e)})"]
    return []
