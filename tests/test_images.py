"""HDR images (data_formats.images): EXR round trip, the Radiance RGBE reader (flat and run-length encoded
scanlines) against hand-encoded files, content sniffing of read_image, and one-line errors for bad files."""

import numpy as np
import pytest

from data_formats.errors import FormatError
from data_formats.images import read_exr, read_hdr, read_image, tonemap, write_exr

HEADER = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y %d +X %d\n"


def rgbe(rgb):
    """The RGBE bytes of one pixel whose values are m/256 · 2^(e−128) exactly (e from the largest component)."""
    peak = max(rgb)
    if peak == 0:
        return bytes(4)
    mant, expo = np.frexp(peak)
    return bytes([int(c * mant * 256 / peak) for c in rgb] + [expo + 128])


def test_exr_round_trip_is_exact(tmp_path):
    img = np.random.default_rng(0).random((5, 7, 3)).astype(np.float32) * 100
    write_exr(tmp_path / "a.exr", img)
    np.testing.assert_array_equal(read_exr(tmp_path / "a.exr"), img)
    np.testing.assert_array_equal(read_image(tmp_path / "a.exr"), img)


def test_flat_rgbe_scanlines_decode_exactly(tmp_path):
    pixels = [[(1.0, 0.5, 0.25), (0.0, 0.0, 0.0)], [(8.0, 2.0, 0.0), (0.125, 0.125, 0.0625)]]
    data = HEADER % (2, 2) + b"".join(rgbe(p) for row in pixels for p in row)
    (tmp_path / "a.hdr").write_bytes(data)
    np.testing.assert_array_equal(read_hdr(tmp_path / "a.hdr"), np.array(pixels, np.float32))
    np.testing.assert_array_equal(read_image(tmp_path / "a.hdr"), np.array(pixels, np.float32))


def test_run_length_encoded_scanline_decodes_runs_and_literals(tmp_path):
    """New-style RLE (width 8 ≥ 8): per channel, a run (count > 128) then literals (count ≤ 128)."""
    width = 8
    row = [(2.0, 1.0, 0.5)] * 5 + [(0.5, 0.25, 0.125), (1.0, 1.0, 1.0), (4.0, 0.0, 2.0)]
    encoded = b"".join(rgbe(p) for p in row)
    channels = [encoded[c::4] for c in range(4)]
    line = bytes([2, 2, 0, width])
    for ch in channels:
        line += bytes([128 + 5, ch[0]]) + bytes([3]) + ch[5:8]
    (tmp_path / "rle.hdr").write_bytes(HEADER % (1, width) + line)
    np.testing.assert_array_equal(read_hdr(tmp_path / "rle.hdr")[0], np.array(row, np.float32))


@pytest.mark.parametrize("data, match", [
    (b"P6\n2 2\n255\n", "not a Radiance HDR file"),
    (b"#?RADIANCE\n\n+X 2 -Y 2\n" + bytes(16), "resolution line"),
    (HEADER % (2, 2) + bytes(10), "truncated pixel data"),
])
def test_bad_hdr_files_are_one_line_errors(tmp_path, data, match):
    (tmp_path / "bad.hdr").write_bytes(data)
    with pytest.raises(FormatError, match=match):
        read_hdr(tmp_path / "bad.hdr")


def test_tonemap_is_srgb_with_exposure_and_clamp():
    img = np.array([[[0.0, 0.5, 2.0], [0.25, 0.001, 1.0]]])
    out = tonemap(img, exposure_stops=1.0)
    assert out.dtype == np.uint8
    np.testing.assert_array_equal(out, [[[0, 255, 255], [188, 7, 255]]])
