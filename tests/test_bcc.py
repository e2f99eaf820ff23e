"""Tests of data_formats.bcc, including files built byte by byte with ``struct`` from the published layout."""

import json
import struct

import numpy as np
import pytest

from data_formats.bcc import describe, read_bcc, sniff, validate, write_bcc
from data_formats.errors import FormatError
from data_formats.yarn_curves import make_yarn_curves

F32_RTOL = 2.0**-24  # float32 round-to-nearest: relative error at most half an ulp (unit roundoff)


def bcc_bytes(curves, curve_type=b"PL", sizes=0x44, dims=3, up=2, info=b"\xff garbage \x01\x02", n_curves=None,
              n_points=None):
    """A BCC file from the published layout: ``curves`` is a list of (signed count, flat xyz list)."""
    n_curves = len(curves) if n_curves is None else n_curves
    n_points = sum(abs(n) for n, _ in curves) if n_points is None else n_points
    out = b"BCC" + struct.pack("<B", sizes) + curve_type + struct.pack("<BB", dims, up)
    out += struct.pack("<QQ", n_curves, n_points) + info.ljust(40, b"\xee")
    assert len(out) == 64
    for n, xyz in curves:
        out += struct.pack("<i", n) + struct.pack(f"<{len(xyz)}f", *xyz)
    return out


OPEN = (3, [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 2.0, 0.0])
LOOP = (-4, [0.0, 0.0, 1.0, 1.0, 0.0, 1.0, 1.0, 1.0, 1.0, 0.0, 1.0, 1.0])


def write(tmp_path, data, name="f.bcc"):
    path = tmp_path / name
    path.write_bytes(data)
    return path


def assert_rejected(path, *fragments):
    with pytest.raises(FormatError) as info:
        read_bcc(path)
    message = str(info.value)
    assert "\n" not in message and str(path) in message
    for fragment in fragments:
        assert fragment in message
    assert validate(path) == [message]


def test_reads_hand_built_file(tmp_path):
    path = write(tmp_path, bcc_bytes([OPEN, LOOP]))
    yc = read_bcc(path, units="cm")
    assert yc.points.shape == (1, 7, 3) and yc.points.dtype == np.float64
    np.testing.assert_array_equal(yc.points[0], np.reshape(OPEN[1] + LOOP[1], (7, 3)))
    assert yc.offsets.tolist() == [0, 3, 7] and yc.closed.tolist() == [False, True]
    assert (yc.curve_type, yc.units, yc.frame_time, yc.yarn_types) == ("PL", "cm", None, ["unknown"])
    assert yc.yarn_type.tolist() == [0, 0]
    np.testing.assert_array_equal(yc.rest_arclength, [0, 1, 3, 0, 1, 2, 3])
    info = json.loads(json.dumps(describe(path)))
    assert info["up_axis"] == "z" and info["kind"] == "bcc" and info["closed_curves"] == 1
    assert info["total_length"] == pytest.approx(3 + 4) and info["bounds"] == [[0, 0, 0], [1, 2, 1]]


def test_writer_output_matches_layout(tmp_path):
    pts = np.array(np.reshape(OPEN[1] + LOOP[1], (7, 3)))
    yc = make_yarn_curves(pts, [0, 3, 7], closed=[False, True], curve_type="BS", units="mm")
    path = tmp_path / "w.bcc"
    write_bcc(path, yc, up_axis="x")
    data = path.read_bytes()
    assert data[:8] == b"BCC\x44BS\x03\x00"
    assert struct.unpack_from("<QQ", data, 8) == (2, 7)
    assert data[24:64].rstrip(b"\0") == b"knit-yarn-curves; units=mm"
    assert struct.unpack_from("<i", data, 64) == (3,)
    assert struct.unpack_from("<9f", data, 68) == tuple(OPEN[1])
    assert struct.unpack_from("<i", data, 104) == (-4,)
    assert struct.unpack_from("<12f", data, 108) == tuple(LOOP[1])
    assert len(data) == 64 + 2 * 4 + 7 * 12


@pytest.mark.parametrize("curve_type", ["BZ", "PL", "C0"])
def test_round_trip_closed_and_curve_types(tmp_path, curve_type):
    rng = np.random.default_rng(3)
    pts = rng.normal(scale=10.0, size=(3, 13, 3))
    yc = make_yarn_curves(pts, [0, 7, 13], closed=[False, True], curve_type=curve_type)  # BZ: 7 = 3*2+1, 6 = 3*2
    path = tmp_path / "r.bcc"
    write_bcc(path, yc, frame=2)
    back = read_bcc(path)
    np.testing.assert_allclose(back.points[0], pts[2], rtol=F32_RTOL, atol=0)  # BCC stores float32
    assert back.offsets.tolist() == [0, 7, 13] and back.closed.tolist() == [False, True]
    assert back.curve_type == curve_type and back.points.shape[0] == 1


def test_free_text_is_ignored(tmp_path):
    a = read_bcc(write(tmp_path, bcc_bytes([OPEN], info=b"units=m yarn=wool\0"), "a.bcc"))
    b = read_bcc(write(tmp_path, bcc_bytes([OPEN], info=bytes(range(200, 240))), "b.bcc"))
    assert a.units == b.units == "unknown" and a.yarn_types == b.yarn_types == ["unknown"]
    assert describe(tmp_path / "a.bcc")["info_text"] == "units=m yarn=wool"


@pytest.mark.parametrize("data, fragments", [
    (b"BCX" + bcc_bytes([OPEN])[3:], ["bad magic b'BCX'", "expected b'BCC'"]),
    (bcc_bytes([OPEN], sizes=0x48), ["0x48", "expected 0x44"]),
    (bcc_bytes([OPEN], dims=2), ["dimensions = 2, expected 3"]),
    (bcc_bytes([OPEN], curve_type=b"XY"), ["curve type b'XY'"]),
    (bcc_bytes([OPEN])[:40], ["truncated header: file has 40 bytes, expected at least 64"]),
    (bcc_bytes([OPEN, LOOP])[:-5], ["truncated: file has 151 bytes", "(2 curves, 7 points) need 156"]),
    (bcc_bytes([OPEN]) + b"\0\0\0\0", ["4 trailing bytes"]),
    (bcc_bytes([OPEN], n_points=4), ["truncated", "(1 curves, 4 points) need 116"]),
    (bcc_bytes([(3, OPEN[1] + [5.0, 5.0, 5.0])], n_points=4), ["curve point counts add up to 3",
                                                                 "expected the header total 4"]),
    (bcc_bytes([(4, LOOP[1]), (2, OPEN[1][:6])], n_points=5)[:-12], ["curve 1: point count 2 runs past the end"]),
    (bcc_bytes([(1, [0.0, 0.0, 0.0]), OPEN]), ["curve 0: point count 1, expected at least 2"]),
    (bcc_bytes([OPEN, (-1, [0.0, 0.0, 0.0])]), ["curve 1: point count -1"]),
    (bcc_bytes([], n_curves=0), ["curve count is 0"]),
    (bcc_bytes([OPEN, (-3, [0, 0, 0, 1, float("nan"), 0, 1, 1, 1])]),
     ["frame 0, curve 1, point 1", "not finite"]),
    (bcc_bytes([OPEN], curve_type=b"BZ"), ["open Bézier curve has 3 points, expected 3k+1"]),
])
def test_corrupt_files_rejected(tmp_path, data, fragments):
    assert_rejected(write(tmp_path, data), *fragments)


def test_counts_past_end_within_consistent_size(tmp_path):
    # header: 4 curves, 2 points -> 64 + 16 + 24 = 104 bytes; the first count (3) swallows every remaining word
    data = bcc_bytes([(3, [1.0] * 9)], n_curves=4, n_points=2)
    assert len(data) == 104
    assert_rejected(write(tmp_path, data), "curve 1: the file ends after 1 of the header's 4 curves")


def test_writer_refuses_nan_and_leaves_no_file(tmp_path):
    pts = np.zeros((2, 4, 3))
    pts[:, :, 0] = np.arange(4)
    pts[1, 3, 2] = np.inf
    yc = make_yarn_curves(pts[:1], [0, 2, 4])
    yc.points = pts
    with pytest.raises(FormatError, match=r"frame 1, curve 1, point 1: .*not finite"):
        write_bcc(tmp_path / "x.bcc", yc)
    assert list(tmp_path.iterdir()) == []


def test_writer_rejects_bad_arguments(tmp_path):
    yc = make_yarn_curves(np.reshape(OPEN[1], (3, 3)), [0, 3])
    with pytest.raises(FormatError, match="frame 1, expected 0 <= frame < 1"):
        write_bcc(tmp_path / "x.bcc", yc, frame=1)
    with pytest.raises(FormatError, match="up_axis 'w'"):
        write_bcc(tmp_path / "x.bcc", yc, up_axis="w")
    assert list(tmp_path.iterdir()) == []


def test_sniff_by_content_never_raises(tmp_path):
    good = write(tmp_path, bcc_bytes([OPEN]), "curves.dat")
    bad = write(tmp_path, b"HDF", "fake.bcc")
    assert sniff(good) and not sniff(bad)
    assert not sniff(tmp_path / "missing.bcc") and not sniff(tmp_path)
    assert validate(good) == []


def test_missing_file_is_a_format_error(tmp_path):
    assert_rejected(tmp_path / "nope.bcc", "no such file, expected a BCC file")
