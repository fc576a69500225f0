"""inflarm_msgs_json.ros.image: sensor_msgs/Image <-> numpy for every encoding, padded rows,
both byte orders, and clear errors for what cannot be read; sensor_msgs/CompressedImage (JPEG,
PNG) <-> BGR as image_transport's compressed transport carries it."""

import array
import struct
import sys

import cv2
import numpy as np
import pytest
from sensor_msgs.msg import CompressedImage, Image
from std_msgs.msg import Header

from inflarm_msgs_json.ros import image as image_module
from inflarm_msgs_json.ros.image import (
    ENCODINGS,
    bgr_to_compressed,
    compressed_format,
    compressed_to_bgr,
    image_to_bgr,
    image_to_numpy,
    numpy_to_image,
)
from vision_scenes import random_case


def sample(encoding: str, height: int = 5, width: int = 6) -> np.ndarray:
    code, channels = ENCODINGS[encoding]
    rng = np.random.default_rng(7)
    shape = (height, width) if channels == 1 else (height, width, channels)
    high = {'u1': 256, 'u2': 65536}.get(code)
    values = rng.integers(0, high, shape) if high else rng.normal(0.0, 100.0, shape)
    return values.astype(code)


def padded(msg: Image, extra: int) -> Image:
    """The same image with ``extra`` junk bytes at the end of every row."""
    rows = np.frombuffer(msg.data, np.uint8).reshape(msg.height, msg.step)
    junk = np.full((msg.height, extra), 0xA5, np.uint8)
    out = Image(height=msg.height, width=msg.width, encoding=msg.encoding,
                is_bigendian=msg.is_bigendian, step=msg.step + extra)
    out.data = array.array('B', np.hstack([rows, junk]).tobytes())
    return out


@pytest.mark.parametrize('encoding', sorted(ENCODINGS))
def test_round_trip_of_every_encoding_with_padding_and_both_byte_orders(encoding):
    pixels = sample(encoding)
    msg = numpy_to_image(pixels, encoding, header=Header(frame_id='cam'))
    code, channels = ENCODINGS[encoding]
    itemsize = np.dtype(code).itemsize
    assert (msg.height, msg.width, msg.encoding) == (5, 6, encoding)
    assert msg.step == 6 * channels * itemsize and len(msg.data) == msg.step * 5
    assert msg.header.frame_id == 'cam'
    back = image_to_numpy(msg)
    assert back.dtype == np.dtype(code) and back.dtype.isnative
    np.testing.assert_array_equal(back, pixels)
    np.testing.assert_array_equal(image_to_numpy(padded(msg, 7)), pixels)

    # the other byte order: the same values come back, in native order
    swapped = pixels.astype(pixels.dtype.newbyteorder('>' if sys.byteorder == 'little' else '<'))
    other = numpy_to_image(swapped, encoding)
    if itemsize > 1:
        assert other.is_bigendian == int(sys.byteorder == 'little')
        assert bytes(other.data) != bytes(msg.data)
    for m in (other, padded(other, 3)):
        out = image_to_numpy(m)
        assert out.dtype.isnative
        np.testing.assert_array_equal(out, pixels)
    # 8-bit data reads the same whatever is_bigendian says
    if itemsize == 1:
        msg.is_bigendian = 1
        np.testing.assert_array_equal(image_to_numpy(msg), pixels)


def test_bgr8_is_read_without_a_copy_and_written_from_one_buffer():
    pixels = sample('bgr8', 48, 64)
    msg = numpy_to_image(pixels, 'bgr8')
    view = image_to_numpy(msg)
    assert np.shares_memory(view, np.frombuffer(msg.data, np.uint8))
    assert image_to_bgr(msg).base is not None
    assert isinstance(msg.data, array.array)


@pytest.mark.parametrize(('encoding', 'code'), [
    ('rgb8', cv2.COLOR_BGR2RGB), ('bgra8', cv2.COLOR_BGR2BGRA), ('rgba8', cv2.COLOR_BGR2RGBA),
])
def test_colour_encodings_convert_to_the_same_bgr(encoding, code):
    bgr = sample('bgr8', 8, 10)
    msg = numpy_to_image(cv2.cvtColor(bgr, code), encoding)
    np.testing.assert_array_equal(image_to_bgr(padded(msg, 5)), bgr)


def test_mono_and_16_bit_encodings_convert_to_grey_bgr():
    grey = sample('mono8', 4, 6)
    np.testing.assert_array_equal(image_to_bgr(numpy_to_image(grey, 'mono8')),
                                  np.repeat(grey[:, :, None], 3, axis=2))
    wide = grey.astype(np.uint16) * 256 + 17
    np.testing.assert_array_equal(image_to_bgr(numpy_to_image(wide, 'mono16'))[:, :, 1], grey)
    bgr16 = sample('bgr8', 4, 6).astype(np.uint16) * 256
    np.testing.assert_array_equal(image_to_bgr(numpy_to_image(bgr16, 'bgr16')),
                                  (bgr16 >> 8).astype(np.uint8))


def test_yuv422_names_follow_ros_uyvy_and_yuyv_byte_orders():
    # a flat colour: each pixel pair is (U, Y, V, Y) in UYVY and (Y, U, Y, V) in YUYV
    y, u, v = 120, 90, 200
    uyvy = np.tile(np.array([u, y, v, y], np.uint8), (2, 2)).reshape(2, 4, 2)
    yuyv = np.tile(np.array([y, u, y, v], np.uint8), (2, 2)).reshape(2, 4, 2)
    # ITU-R BT.601, limited range (video levels), the conversion V4L2 4:2:2 cameras use
    luma = 1.164 * (y - 16)
    expected = np.array([luma + 2.018 * (u - 128),
                         luma - 0.813 * (v - 128) - 0.391 * (u - 128),
                         luma + 1.596 * (v - 128)])
    for name, data in (('uyvy', uyvy), ('yuv422', uyvy), ('yuyv', yuyv),
                       ('yuv422_yuy2', yuyv)):
        bgr = image_to_bgr(numpy_to_image(data, name))
        assert bgr.shape == (2, 4, 3)
        np.testing.assert_allclose(bgr.reshape(-1, 3), np.tile(expected, (8, 1)), atol=2)
    # reading UYVY bytes as YUYV gives another colour: the names are not interchangeable
    wrong = image_to_bgr(numpy_to_image(uyvy, 'yuyv'))
    assert np.abs(wrong.astype(int) - expected).max() > 20


def test_unreadable_images_are_value_errors_that_say_why():
    good = numpy_to_image(sample('bgr8', 4, 6), 'bgr8')

    def variant(**fields) -> Image:
        msg = Image(height=good.height, width=good.width, encoding=good.encoding,
                    step=good.step)
        msg.data = good.data
        for name, value in fields.items():
            setattr(msg, name, value)
        return msg

    cases = [
        (variant(encoding='hsv8'), "unsupported image encoding 'hsv8'"),
        (variant(height=0, width=0, step=0, data=array.array('B')), 'empty image'),
        (variant(data=good.data[:-5]), r'truncated'),
        (variant(data=good.data + array.array('B', [0] * 3)), 'bytes of data, got 75'),
        (variant(step=10), 'step 10 is smaller than a row'),
        (variant(height=5), r'18 \* 5 = 90 bytes of data, got 72'),
    ]
    for msg, match in cases:
        with pytest.raises(ValueError, match=match):
            image_to_numpy(msg)
    with pytest.raises(ValueError, match='even width'):
        image_to_numpy(Image(height=1, width=3, encoding='yuyv', step=6,
                             data=array.array('B', bytes(6))))
    with pytest.raises(ValueError, match="BGR image from encoding '32FC1'"):
        image_to_bgr(numpy_to_image(sample('32FC1'), '32FC1'))
    with pytest.raises(ValueError, match=r"shape \(height, width, 3\) for 'bgr8'"):
        numpy_to_image(np.zeros((4, 4), np.uint8), 'bgr8')
    with pytest.raises(ValueError, match="dtype uint16 for 'mono16'"):
        numpy_to_image(np.zeros((4, 4), np.uint8), 'mono16')


# -- CompressedImage ----------------------------------------------------------------------------

def scene() -> np.ndarray:
    """A camera-like 640x480 image of the ball (noise background, blur, sensor noise)."""
    return random_case(np.random.default_rng(7), 'noise').frame.image


def compressed(data: bytes, fmt: str = 'bgr8; jpeg compressed bgr8') -> CompressedImage:
    msg = CompressedImage(format=fmt)
    msg.data = array.array('B', data)
    return msg


def test_jpeg_round_trip_is_close_and_png_round_trip_exact():
    bgr = scene()
    header = Header(frame_id='camera_optical_frame')
    header.stamp.sec = 12
    jpeg = bgr_to_compressed(bgr, 'jpeg', 90, header)
    assert jpeg.format == 'bgr8; jpeg compressed bgr8'  # image_transport's format string
    assert (jpeg.header.stamp.sec, jpeg.header.frame_id) == (12, 'camera_optical_frame')
    assert isinstance(jpeg.data, array.array)
    assert bytes(jpeg.data[:3]) == b'\xff\xd8\xff'
    decoded = compressed_to_bgr(jpeg)
    assert decoded.shape == bgr.shape and decoded.dtype == np.uint8
    error = decoded.astype(float) - bgr
    psnr = 10.0 * np.log10(255.0 ** 2 / np.mean(error ** 2))
    # measured at quality 90: PSNR 40.0 dB, mean absolute error 2.0 grey levels
    assert psnr > 36.0 and np.abs(error).mean() < 3.0, (psnr, np.abs(error).mean())
    assert len(jpeg.data) < bgr.nbytes / 10
    # a lower quality is smaller and further off
    rough = bgr_to_compressed(bgr, quality=30)
    assert len(rough.data) < len(jpeg.data)
    assert np.abs(compressed_to_bgr(rough).astype(float) - bgr).mean() > np.abs(error).mean()

    png = bgr_to_compressed(bgr, 'png')
    assert png.format == 'bgr8; png compressed bgr8'
    np.testing.assert_array_equal(compressed_to_bgr(png), bgr)
    # a non-contiguous view encodes as its pixels
    np.testing.assert_array_equal(compressed_to_bgr(bgr_to_compressed(bgr[::2, ::-2], 'png')),
                                  bgr[::2, ::-2])


@pytest.mark.parametrize(('fmt', 'kind'), [
    ('bgr8; jpeg compressed bgr8', 'jpeg'), ('rgb8; jpeg compressed bgr8', 'jpeg'),
    ('mono8; jpeg compressed mono8', 'jpeg'), ('bgr8; png compressed bgr8', 'png'),
    ('mono16; png compressed', 'png'), ('jpeg', 'jpeg'), ('JPEG', 'jpeg'), ('jpg', 'jpeg'),
    ('png', 'png'), (' png ', 'png'),
])
def test_image_transport_and_bare_format_strings_are_read(fmt, kind):
    assert compressed_format(fmt) == kind


@pytest.mark.parametrize('fmt', [
    'theora', '', 'compressedDepth', '16UC1; compressedDepth png', '32FC1; compressedDepth',
    'tiff', 'bgr8; bmp compressed bgr8', 'bgr8; jpeg encoded',
])
def test_other_formats_are_refused_naming_them(fmt):
    with pytest.raises(ValueError, match=f"unsupported compressed image format '{fmt}'"):
        compressed_format(fmt)
    with pytest.raises(ValueError, match='unsupported compressed image format'):
        compressed_to_bgr(compressed(bytes(bgr_to_compressed(scene()).data), fmt))


def test_bare_formats_and_grey_images_decode_to_bgr():
    grey = scene()[:, :, 1]
    ok, encoded = cv2.imencode('.png', grey)
    bgr = compressed_to_bgr(compressed(encoded.tobytes(), 'png'))
    np.testing.assert_array_equal(bgr, np.repeat(grey[:, :, None], 3, axis=2))
    ok, encoded = cv2.imencode('.jpg', scene())
    assert compressed_to_bgr(compressed(encoded.tobytes(), 'jpeg')).shape == (480, 640, 3)


def test_an_exif_orientation_does_not_turn_the_sensor_s_pixels():
    bgr = scene()
    data = bytes(bgr_to_compressed(bgr).data)
    # APP1 Exif with orientation 6 (rotate 90 degrees) right after SOI
    tiff = (b'II*\x00' + struct.pack('<IH', 8, 1) + struct.pack('<HHII', 0x0112, 3, 1, 6)
            + struct.pack('<I', 0))
    app1 = b'Exif\x00\x00' + tiff
    tagged = data[:2] + b'\xff\xe1' + struct.pack('>H', len(app1) + 2) + app1 + data[2:]
    assert cv2.imdecode(np.frombuffer(tagged, np.uint8), cv2.IMREAD_COLOR).shape[:2] == (640, 480)
    assert compressed_to_bgr(compressed(tagged)).shape == (480, 640, 3)


def test_bad_compressed_data_are_value_errors_that_say_why():
    jpeg = bytes(bgr_to_compressed(scene()).data)
    png = bytes(bgr_to_compressed(scene(), 'png').data)
    junk = bytes(np.random.default_rng(7).integers(0, 256, len(jpeg) - 3, np.uint8))
    cases = [
        (compressed(b''), 'empty jpeg data'),
        (compressed(b'', 'png'), 'empty png data'),
        (compressed(jpeg, 'bgr8; png compressed bgr8'),
         r"is not png \(format 'bgr8; png compressed bgr8'\): it starts with b'.xff.xd8"),
        (compressed(png, 'jpeg'), r"is not jpeg \(format 'jpeg'\): it starts with b'.x89PNG'"),
        (compressed(b'\xff\xd8'), 'not jpeg'),  # shorter than a signature
        (compressed(jpeg[:len(jpeg) // 2]), f'corrupt jpeg data: {len(jpeg) // 2} bytes'),
        (compressed(jpeg[:-2]), 'corrupt jpeg data'),  # without its end-of-image marker
        (compressed(jpeg[:3] + junk), 'corrupt jpeg data'),
        (compressed(png[:len(png) // 2], 'png'), 'corrupt png data'),
    ]
    for msg, match in cases:
        with pytest.raises(ValueError, match=match):
            compressed_to_bgr(msg)
    for image, match in [(np.zeros((4, 4), np.uint8), r'shape \(height, width, 3\)'),
                         (np.zeros((4, 4, 3), np.uint16), 'uint16'),
                         (np.zeros((0, 4, 3), np.uint8), 'non-empty')]:
        with pytest.raises(ValueError, match=match):
            bgr_to_compressed(image)
    for quality in (0, 101, 90.5, '90', None, True):
        with pytest.raises(ValueError, match='JPEG quality integer in 1-100'):
            bgr_to_compressed(scene(), quality=quality)
    with pytest.raises(ValueError, match="unsupported compressed image format 'theora'"):
        bgr_to_compressed(scene(), 'theora')


def test_the_decode_reads_the_message_s_buffer_itself(monkeypatch):
    msg = bgr_to_compressed(scene())
    seen = []
    decode = cv2.imdecode

    def spy(buffer, flags):
        seen.append(buffer)
        return decode(buffer, flags)

    monkeypatch.setattr(image_module.cv2, 'imdecode', spy)
    assert compressed_to_bgr(msg).shape == (480, 640, 3)
    (buffer,) = seen
    assert np.shares_memory(buffer, np.frombuffer(msg.data, np.uint8))  # no copy before it
