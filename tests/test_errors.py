"""``data_formats.errors.read_problems``: the ``validate`` of every reader."""

import pytest

from data_formats.errors import FormatError, read_problems


def _reader(error):
    def read(path):
        if error is not None:
            raise error
    return read


def test_read_problems_reports_format_errors_and_lets_bugs_through():
    assert read_problems(_reader(None), "f.h5") == []
    assert read_problems(_reader(FormatError("f.h5: bad\nthing")), "f.h5") == ["f.h5: bad\nthing"]
    with pytest.raises(KeyError):  # not bad input: a bug, which must not pass as a validation problem
        read_problems(_reader(KeyError("x")), "f.h5")
    assert read_problems(_reader(OSError("corrupt\n  internals")), "f.h5", any_error=True) == \
        ["f.h5: unreadable (OSError: corrupt internals)"]
