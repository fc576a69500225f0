"""``sensor_msgs/Image`` to and from numpy arrays, without cv_bridge (not on PyPI).

In the spirit of cv_bridge's ``imgmsg_to_cv2`` / ``cv2_to_imgmsg``:

- `image_to_numpy(msg)`: the pixels as an array, ``(height, width)`` for one channel,
  ``(height, width, channels)`` otherwise, in native byte order. For 8-bit data it is a view
  of ``msg.data`` (no copy; writing to it writes the message), with row padding (``step``)
  skipped by strides. Multi-byte data whose ``is_bigendian`` differs from this machine's is
  byte-swapped into a copy.
- `image_to_bgr(msg)`: an 8-bit BGR array for the colour and mono encodings (OpenCV's
  conversions; a view for ``bgr8``).
- `numpy_to_image(array, encoding, header=None)`: a message with ``step = width * pixel
  bytes`` (no padding) and ``is_bigendian`` from the array's byte order. The pixels go into
  ``msg.data`` as one ``array.array`` built from the buffer (one copy); never assign an
  ndarray to ``msg.data``: rosidl converts it element by element.

``benchmarks/bench_vision.py`` times both conversions; ``inflarm_msgs_json/README.md`` says what
the element-by-element conversion costs.

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

``sensor_msgs/CompressedImage``, as ``image_transport``'s ``compressed`` transport carries it:

- `compressed_to_bgr(msg)`: the decoded 8-bit BGR array (``cv2.imdecode`` on a view of
  ``msg.data``: the decode is the only copy). ``format`` is image_transport's
  ``"<encoding>; jpeg compressed <encoding>"`` (or ``png``) or a bare ``jpeg`` / ``png``, as
  camera drivers write it; the data must be of that format (JPEG or PNG signature).
- `bgr_to_compressed(image, fmt='jpeg', quality=90, header=None)`: a message with
  image_transport's format string, JPEG at ``quality`` (OpenCV's default 4:2:0 chroma
  subsampling, libjpeg's default) or PNG.
- `compressed_format(fmt)`: ``'jpeg'`` or ``'png'`` from a ``format`` string, else a
  ``ValueError`` naming it.
"""

import array
import numbers
import sys

import cv2
import numpy as np
import numpy.typing as npt
from sensor_msgs.msg import CompressedImage, Image
from std_msgs.msg import Header

__all__ = [
    'ENCODINGS',
    'bgr_to_compressed',
    'compressed_format',
    'compressed_to_bgr',
    'image_to_bgr',
    'image_to_numpy',
    'numpy_to_image',
]

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


_SIGNATURES = {'jpeg': b'\xff\xd8\xff', 'png': b'\x89PNG\r\n\x1a\n'}
_FORMAT_NAMES = {'jpeg': 'jpeg', 'jpg': 'jpeg', 'png': 'png'}


def compressed_format(fmt: str) -> str:
    """``'jpeg'`` or ``'png'``: the compression named by a ``CompressedImage.format``.

    Accepts image_transport's ``"bgr8; jpeg compressed bgr8"`` / ``"mono16; png compressed"``
    and a bare ``"jpeg"``, ``"jpg"`` or ``"png"`` (case-insensitive).

    Raises
    ------
    ValueError
        Any other format (``theora``, ``tiff``, ``compressedDepth``, empty).
    """
    text = str(fmt).strip().lower()
    words = text.split(';', 1)[-1].split()
    if words and words[0] in _FORMAT_NAMES and (len(words) == 1 or words[1] == 'compressed'):
        return _FORMAT_NAMES[words[0]]
    raise ValueError(f"unsupported compressed image format '{fmt}'; supported: jpeg, png "
                     "(image_transport's compressed transport)")


def compressed_to_bgr(msg: CompressedImage) -> npt.NDArray[np.uint8]:
    """The 8-bit BGR image of a ``sensor_msgs/CompressedImage`` (JPEG or PNG).

    An EXIF orientation tag is ignored: the array is the sensor's pixel grid.

    Raises
    ------
    ValueError
        An unsupported ``format``, empty data, data that is not of the declared format, or
        bytes that do not decode (truncated, or corrupt headers). Damaged entropy-coded JPEG
        data that libjpeg resynchronises on decodes, to a damaged image.
    """
    kind = compressed_format(msg.format)
    data = np.frombuffer(msg.data, dtype=np.uint8)
    if data.size == 0:
        raise ValueError(f'empty {kind} data in a CompressedImage')
    signature = _SIGNATURES[kind]
    if data[:len(signature)].tobytes() != signature:
        raise ValueError(f"CompressedImage data is not {kind} (format '{msg.format}'): it starts "
                         f'with {data[:4].tobytes()!r}')
    # the pixels as the sensor delivered them, which camera_info describes: an EXIF
    # orientation tag does not rotate them (nor in image_transport's default mode, unchanged)
    bgr = cv2.imdecode(data, cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION)
    if bgr is None:
        raise ValueError(f'corrupt {kind} data: {data.size} bytes that OpenCV cannot decode')
    return bgr


def bgr_to_compressed(bgr: npt.ArrayLike, fmt: str = 'jpeg', quality: int = 90,
                      header: Header | None = None) -> CompressedImage:
    """A ``sensor_msgs/CompressedImage`` of an 8-bit BGR image.

    Parameters
    ----------
    bgr : array-like, shape (height, width, 3), uint8
    fmt : {'jpeg', 'png'}
    quality : int
        JPEG quality, 1-100 (ignored for PNG).
    header : std_msgs.msg.Header, optional

    Returns
    -------
    sensor_msgs.msg.CompressedImage
        ``format`` as image_transport writes it: ``"bgr8; jpeg compressed bgr8"`` or
        ``"bgr8; png compressed bgr8"``.
    """
    kind = compressed_format(fmt)
    a = np.asarray(bgr)
    if a.ndim != 3 or a.shape[2] != 3 or a.dtype != np.uint8 or a.shape[0] == 0 \
            or a.shape[1] == 0:
        raise ValueError(f'expected a non-empty uint8 BGR array of shape (height, width, 3), '
                         f'got {a.dtype} {a.shape}')
    if isinstance(quality, bool) or not isinstance(quality, numbers.Integral) \
            or not 1 <= quality <= 100:
        raise ValueError(f'expected a JPEG quality integer in 1-100, got {quality!r}')
    flags = [cv2.IMWRITE_JPEG_QUALITY, int(quality)] if kind == 'jpeg' else []
    ok, encoded = cv2.imencode('.jpg' if kind == 'jpeg' else '.png', a, flags)
    if not ok:
        raise ValueError(f'OpenCV could not encode a {a.shape[1]}x{a.shape[0]} image as {kind}')
    msg = CompressedImage(format=f'bgr8; {kind} compressed bgr8')
    if header is not None:
        msg.header = header
    data = array.array('B')
    data.frombytes(encoded.reshape(-1))
    msg.data = data
    return msg
