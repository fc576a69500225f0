"""``sensor_msgs/Image`` to and from numpy arrays, without cv_bridge (not on PyPI).

In the spirit of cv_bridge's ``imgmsg_to_cv2`` / ``cv2_to_imgmsg``:

- `image_to_numpy(msg)`: the pixels as an array, ``(height, width)`` for one channel,
  ``(height, width, channels)`` otherwise, in native byte order. For 8-bit data it is a view
  of ``msg.data`` (no copy, about 10 us for 1920x1080 bgr8; writing to it writes the message),
  with row padding (``step``) skipped by strides. Multi-byte data whose ``is_bigendian`` differs
  from this machine's is byte-swapped into a copy.
- `image_to_bgr(msg)`: an 8-bit BGR array for the colour and mono encodings (OpenCV's
  conversions; a view for ``bgr8``).
- `numpy_to_image(array, encoding, header=None)`: a message with ``step = width * pixel
  bytes`` (no padding) and ``is_bigendian`` from the array's byte order. The pixels go into
  ``msg.data`` as one ``array.array`` built from the buffer (about 1 ms for 1920x1080 bgr8);
  never assign an ndarray to ``msg.data``: rosidl converts it element by element (about
  100 ms at 640x480).

Encodings (names of ``sensor_msgs/image_encodings.hpp``):

==========================  =======  ========  ===============================================
encoding                    dtype    channels  note
==========================  =======  ========  ===============================================
bgr8, rgb8                  uint8    3
bgra8, rgba8                uint8    4
mono8, 8UC1                 uint8    1
8UC3, 8UC4                  uint8    3, 4      no colour order implied (BGR assumed for
                                               `image_to_bgr`)
mono16, 16UC1               uint16   1         ``is_bigendian`` honoured
bgr16, rgb16                uint16   3         ``is_bigendian`` honoured
32FC1                       float32  1         ``is_bigendian`` honoured; not convertible to
                                               BGR
uyvy, yuv422                uint8    2         packed 4:2:2, byte order U Y0 V Y1 (fourcc
                                               UYVY). ROS's ``yuv422`` is UYVY (deprecated
                                               name, same layout)
yuyv, yuv422_yuy2           uint8    2         packed 4:2:2, byte order Y0 U Y1 V (fourcc
                                               YUYV / YUY2). ROS's ``yuv422_yuy2`` is YUYV
==========================  =======  ========  ===============================================

For the 4:2:2 encodings the array is ``(height, width, 2)`` bytes, two per pixel, as cv_bridge
returns them; ``width`` must be even. Every problem (unknown encoding, empty image, ``step``
too small, data not ``step * height`` bytes, an array that does not fit the encoding) is a
``ValueError`` that says what is wrong.
"""

import array
import sys

import cv2
import numpy as np
import numpy.typing as npt
from sensor_msgs.msg import Image
from std_msgs.msg import Header

__all__ = ['ENCODINGS', 'image_to_bgr', 'image_to_numpy', 'numpy_to_image']

ENCODINGS: dict[str, tuple[str, int]] = {
    'bgr8': ('u1', 3), 'rgb8': ('u1', 3), 'bgra8': ('u1', 4), 'rgba8': ('u1', 4),
    'mono8': ('u1', 1), '8UC1': ('u1', 1), '8UC3': ('u1', 3), '8UC4': ('u1', 4),
    'mono16': ('u2', 1), '16UC1': ('u2', 1), 'bgr16': ('u2', 3), 'rgb16': ('u2', 3),
    '32FC1': ('f4', 1),
    'uyvy': ('u1', 2), 'yuv422': ('u1', 2), 'yuyv': ('u1', 2), 'yuv422_yuy2': ('u1', 2),
}
"""Supported encodings: name -> (numpy dtype code, channels)."""

_PACKED_422 = ('uyvy', 'yuv422', 'yuyv', 'yuv422_yuy2')
_TO_BGR = {
    'rgb8': cv2.COLOR_RGB2BGR, 'bgra8': cv2.COLOR_BGRA2BGR, 'rgba8': cv2.COLOR_RGBA2BGR,
    'mono8': cv2.COLOR_GRAY2BGR, '8UC1': cv2.COLOR_GRAY2BGR, '8UC4': cv2.COLOR_BGRA2BGR,
    'uyvy': cv2.COLOR_YUV2BGR_UYVY, 'yuv422': cv2.COLOR_YUV2BGR_UYVY,
    'yuyv': cv2.COLOR_YUV2BGR_YUYV, 'yuv422_yuy2': cv2.COLOR_YUV2BGR_YUYV,
}
_NATIVE_BIG = sys.byteorder == 'big'


def _layout(encoding: str) -> tuple[np.dtype, int]:
    if encoding not in ENCODINGS:
        raise ValueError(f"unsupported image encoding '{encoding}'; supported: "
                         f'{", ".join(ENCODINGS)}')
    code, channels = ENCODINGS[encoding]
    return np.dtype(code), channels


def image_to_numpy(msg: Image) -> npt.NDArray:
    """The pixels of a ``sensor_msgs/Image``.

    Parameters
    ----------
    msg : sensor_msgs.msg.Image

    Returns
    -------
    ndarray, shape (height, width) or (height, width, channels)
        Native byte order; a view of ``msg.data`` unless it had to be byte-swapped.

    Raises
    ------
    ValueError
        Unknown encoding, empty image, odd width for 4:2:2, ``step`` smaller than a row, or
        ``len(data) != step * height``.
    """
    dtype, channels = _layout(msg.encoding)
    height, width, step = int(msg.height), int(msg.width), int(msg.step)
    if height == 0 or width == 0:
        raise ValueError(f'empty image: height {height}, width {width}')
    if msg.encoding in _PACKED_422 and width % 2:
        raise ValueError(f"expected an even width for '{msg.encoding}' (4:2:2), got {width}")
    row_bytes = width * channels * dtype.itemsize
    if step < row_bytes:
        raise ValueError(
            f"step {step} is smaller than a row of {width} '{msg.encoding}' pixels "
            f'({row_bytes} bytes)')
    size = len(msg.data)
    if size != step * height:
        raise ValueError(
            f'expected step * height = {step} * {height} = {step * height} bytes of data, got '
            f'{size}' + (' (truncated)' if size < step * height else ''))
    big = bool(msg.is_bigendian)
    raw = np.frombuffer(msg.data, dtype=np.uint8)
    rows = raw.reshape(height, step)[:, :row_bytes]
    if dtype.itemsize == 1:
        pixels = rows.reshape(height, width, channels)
    else:
        # rows keep their padding stride; the last axis is contiguous, so the dtype can change
        pixels = rows.view(dtype.newbyteorder('>' if big else '<')).reshape(
            height, width, channels)
        if big != _NATIVE_BIG:
            pixels = pixels.astype(dtype.newbyteorder('='))
    return pixels[:, :, 0] if channels == 1 else pixels


def image_to_bgr(msg: Image) -> npt.NDArray[np.uint8]:
    """An 8-bit BGR array of a colour or mono ``sensor_msgs/Image``.

    16-bit encodings keep their high byte. ``bgr8`` (and ``8UC3``) come as a view of the
    message's data; the others as a new array (``cv2.cvtColor``).

    Raises
    ------
    ValueError
        As `image_to_numpy`, or an encoding without colour (``32FC1``).
    """
    pixels = image_to_numpy(msg)
    encoding = msg.encoding
    if encoding in ('bgr8', '8UC3'):
        return pixels
    if pixels.dtype == np.uint16:
        pixels = (pixels >> 8).astype(np.uint8)
        encoding = {'mono16': 'mono8', '16UC1': 'mono8', 'bgr16': 'bgr8',
                    'rgb16': 'rgb8'}[encoding]
        if encoding == 'bgr8':
            return pixels
    if encoding not in _TO_BGR:
        raise ValueError(f"cannot make a BGR image from encoding '{msg.encoding}'")
    if not pixels.flags.c_contiguous:
        pixels = np.ascontiguousarray(pixels)
    return cv2.cvtColor(pixels, _TO_BGR[encoding])


def numpy_to_image(pixels: npt.ArrayLike, encoding: str,
                   header: Header | None = None) -> Image:
    """A ``sensor_msgs/Image`` holding an array.

    Parameters
    ----------
    pixels : array-like, shape (height, width) or (height, width, channels)
        dtype and channels as the encoding requires (see the module table); a big-endian
        array gives ``is_bigendian = 1``.
    encoding : str
    header : std_msgs.msg.Header, optional
        Stamp and frame of the image.

    Returns
    -------
    sensor_msgs.msg.Image
        ``step = width * channels * itemsize``.
    """
    dtype, channels = _layout(encoding)
    a = np.asarray(pixels)
    if a.ndim == 2 and channels == 1:
        a = a[:, :, None]
    if a.ndim != 3 or a.shape[2] != channels:
        shape = '(height, width)' if channels == 1 else f'(height, width, {channels})'
        raise ValueError(f"expected an array of shape {shape} for '{encoding}', got {a.shape}")
    if a.dtype.kind != dtype.kind or a.dtype.itemsize != dtype.itemsize:
        raise ValueError(f"expected dtype {dtype} for '{encoding}', got {a.dtype}")
    if a.shape[0] == 0 or a.shape[1] == 0:
        raise ValueError(f'empty image: shape {a.shape}')
    if encoding in _PACKED_422 and a.shape[1] % 2:
        raise ValueError(f"expected an even width for '{encoding}' (4:2:2), got {a.shape[1]}")
    big = a.dtype.byteorder == '>' or (a.dtype.byteorder == '=' and _NATIVE_BIG)
    a = np.ascontiguousarray(a)
    data = array.array('B')
    data.frombytes(a.reshape(-1).view(np.uint8))
    msg = Image(height=a.shape[0], width=a.shape[1], encoding=encoding,
                is_bigendian=int(big and dtype.itemsize > 1),
                step=a.shape[1] * channels * dtype.itemsize)
    if header is not None:
        msg.header = header
    msg.data = data
    return msg
