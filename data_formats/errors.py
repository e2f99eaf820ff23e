"""The one error type every reader, writer and validator in ``data_formats`` raises for bad input.

A ``FormatError`` message is a single line that names the file or field, the bad value, and what was expected, so
the CLI can print it as is (``knitbake: error: <message>``) without a traceback.
"""


class FormatError(ValueError):
    """Malformed, corrupt or out-of-range input; the message is one line naming what is wrong."""
