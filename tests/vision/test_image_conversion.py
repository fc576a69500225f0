"""inflarm_msgs_json.ros.image: sensor_msgs/Image <-> numpy for every encoding, padded rows,
both byte orders, and clear errors for what cannot be read."""

import array
import sys

import cv2
import numpy as np
import pytest
from sensor_msgs.msg import Image
from std_msgs.msg import Header

from inflarm_msgs_json.ros.image import (
    ENCODINGS,
    image_to_bgr,
    image_to_numpy,
    numpy_to_image,
)


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
