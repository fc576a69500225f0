"""Frames from a camera or a video file through OpenCV's ``cv2.VideoCapture``: the core of the
``camera_driver`` node (no ROS here).

Sources (`source_kind`):

- a V4L2 device, ``'/dev/video0'``, or its index as a string, ``'0'`` (OpenCV's V4L2 backend on
  Linux, its default backend elsewhere). ``width``, ``height``, ``fps`` and ``fourcc`` are
  requested from the device (in that order after the fourcc, as V4L2 wants them); the device
  may settle on other values, which `VideoSource` reports (``width``, ``height``, ``fps``,
  ``fourcc``). A device is paced by itself.
- anything else is a video file, read with OpenCV's FFmpeg backend (a recording replayed by
  tests or by users without a camera). Its own size and codec are used (``width``, ``height``
  and ``fourcc`` do not apply); it is paced to ``fps`` (its recorded rate when ``fps`` is 0,
  30 Hz if it has none), since OpenCV reads a file as fast as it can, and restarts at its end
  when ``loop``.

JPEG pass-through (``jpeg_passthrough``): an MJPEG source's frames are handed out as the
compressed JPEG bytes it delivered, without a decode and a re-encode:

- FFmpeg backend (files): ``cap.set(cv2.CAP_PROP_FORMAT, -1)`` makes ``retrieve`` return the
  encoded packet, a ``(1, n)`` uint8 array; in an MJPG AVI each packet is one complete JPEG
  (``FF D8 FF`` ... ``FF D9``). Checked with opencv-python-headless 5.0 on files written by
  ``cv2.VideoWriter`` with fourcc MJPG (``tests/vision/test_capture.py``).
- V4L2 backend (devices): ``cap.set(cv2.CAP_PROP_CONVERT_RGB, 0)`` makes ``retrieve`` return
  the driver's buffer, for an MJPG mode the camera's JPEG. Not tested here: this machine has
  no ``/dev/video*``.

Every packet is checked for the JPEG signature ``FF D8 FF`` and a frame header (`jpeg_size`);
the first that fails (another codec: MPEG-4, H.264, a YUYV device mode) switches the source to
decoded frames for good (it is reopened without pass-through: the FFmpeg backend cannot switch
back in place), so a `Frame` holds either ``jpeg`` bytes or a decoded ``bgr`` array.

Errors are `CaptureError` (a ``ValueError``) naming the source: a device or file that is not
there or cannot be opened, a device that fails to deliver frames `MAX_READ_FAILURES` times in a
row, a file with no frame. Bad settings (a fourcc that is not 4 characters, a negative size)
are ``ValueError`` from `CaptureSettings`.
"""

from collections.abc import Callable
from dataclasses import dataclass
import math
import os
import sys
import time

import cv2
import numpy as np
import numpy.typing as npt

__all__ = [
    'JPEG_SIGNATURE',
    'MAX_READ_FAILURES',
    'CaptureError',
    'CaptureSettings',
    'Frame',
    'VideoSource',
    'jpeg_size',
    'source_kind',
]

JPEG_SIGNATURE = b'\xff\xd8\xff'
MAX_READ_FAILURES = 3
"""Failed reads in a row after which a device counts as gone (`CaptureError`)."""
DEFAULT_FILE_FPS = 30.0
"""Pace of a file that records no frame rate, when ``fps`` is 0 [Hz]."""

# Start-of-frame markers (baseline, extended, progressive, lossless; Huffman and arithmetic).
_SOF_MARKERS = frozenset((0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD,
                          0xCE, 0xCF))
_STANDALONE_MARKERS = frozenset((0x01, *range(0xD0, 0xD9)))  # TEM, RST0-7, SOI


class CaptureError(ValueError):
    """A source that cannot be opened or read; ``source`` is its name as given."""

    def __init__(self, source: str, message: str) -> None:
        super().__init__(f"video source '{source}': {message}")
        self.source = source


def source_kind(device: str) -> str:
    """``'index'`` for ``'0'``, ``'1'``..., ``'device'`` for a path under ``/dev/``, else
    ``'file'``."""
    text = device.strip()
    if text.isdigit():
        return 'index'
    if text.startswith('/dev/'):
        return 'device'
    return 'file'


def jpeg_size(data: bytes) -> tuple[int, int]:
    """``(width, height)`` [px] from a JPEG's frame header (SOF), without decoding it.

    Raises
    ------
    ValueError
        ``data`` does not start with the JPEG signature ``FF D8 FF``, or has no readable frame
        header before its scan data.
    """
    data = bytes(data)
    if not data.startswith(JPEG_SIGNATURE):
        raise ValueError(f'not a JPEG: starts with {bytes(data[:4])!r}')
    i, n = 2, len(data)
    while i + 4 <= n:
        if data[i] != 0xFF:
            raise ValueError(f'corrupt JPEG: no marker at byte {i}')
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker in _STANDALONE_MARKERS:
            i += 2
            continue
        if marker in (0xD9, 0xDA):  # end of image, start of scan: no frame header before
            break
        if marker in _SOF_MARKERS and i + 9 <= n:
            height = int.from_bytes(data[i + 5:i + 7], 'big')
            width = int.from_bytes(data[i + 7:i + 9], 'big')
            if width == 0 or height == 0:
                raise ValueError(f'JPEG frame header gives a size of {width}x{height}')
            return width, height
        i += 2 + int.from_bytes(data[i + 2:i + 4], 'big')
    raise ValueError('JPEG without a frame header (SOF)')


@dataclass(frozen=True)
class CaptureSettings:
    """What to open and how.

    Parameters
    ----------
    device : str
        ``'/dev/video0'``, a device index ``'0'``, or a video file's path.
    width, height : int
        Requested image size of a device [px]; 0 keeps the device's default.
    fps : float
        Frame rate [Hz]: requested from a device (0 keeps its default); the pace of a file (0:
        its recorded rate).
    fourcc : str
        Pixel format requested from a device, 4 characters (``'MJPG'``, ``'YUYV'``), or ``''``
        to keep its default.
    loop : bool
        Restart a file at its end (devices have none).
    pace : bool
        Pace a file to its rate; False reads it as fast as possible.
    jpeg_passthrough : bool
        Hand out an MJPEG source's JPEG bytes as they come (``Frame.jpeg``) instead of decoded
        images.
    """

    device: str
    width: int = 0
    height: int = 0
    fps: float = 0.0
    fourcc: str = 'MJPG'
    loop: bool = True
    pace: bool = True
    jpeg_passthrough: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.device, str) or not self.device.strip():
            raise ValueError(f"expected a device ('/dev/video0', '0') or a video file, got "
                             f'{self.device!r}')
        for name in ('width', 'height'):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 16384:
                raise ValueError(f'expected {name} an integer in 0-16384 [px] (0: the '
                                 f"source's default), got {value!r}")
        if not (isinstance(self.fps, (int, float)) and math.isfinite(self.fps)
                and 0.0 <= self.fps <= 1000.0):
            raise ValueError(f"expected fps in 0-1000 Hz (0: the source's rate), got "
                             f'{self.fps!r}')
        if not isinstance(self.fourcc, str) or (
                self.fourcc and (len(self.fourcc) != 4 or not self.fourcc.isascii()
                                 or not self.fourcc.isprintable())):
            raise ValueError(f"expected a fourcc of 4 ASCII characters (e.g. 'MJPG', 'YUYV') "
                             f"or '' for the device's default, got {self.fourcc!r}")

    @property
    def kind(self) -> str:
        """``'index'``, ``'device'`` or ``'file'`` (`source_kind`)."""
        return source_kind(self.device)


@dataclass(frozen=True)
class Frame:
    """One captured frame: either the source's JPEG bytes or a decoded image.

    Attributes
    ----------
    index : int
        Frames handed out by the source before this one (it keeps counting over loops).
    stamp : object
        What the source's ``clock()`` returned right after the frame was grabbed.
    width, height : int
        Image size [px].
    jpeg : bytes or None
        The JPEG exactly as the source delivered it (pass-through), else None.
    bgr : ndarray, shape (height, width, 3), uint8, or None
        The decoded image, when there is no ``jpeg``.
    """

    index: int
    stamp: object
    width: int
    height: int
    jpeg: bytes | None = None
    bgr: npt.NDArray[np.uint8] | None = None

    def image(self) -> npt.NDArray[np.uint8]:
        """The BGR image, decoded from ``jpeg`` if needed.

        Raises
        ------
        ValueError
            JPEG bytes OpenCV cannot decode.
        """
        if self.bgr is not None:
            return self.bgr
        bgr = cv2.imdecode(np.frombuffer(self.jpeg, np.uint8), cv2.IMREAD_COLOR)
        if bgr is None:
            raise ValueError(f'frame {self.index}: {len(self.jpeg)} bytes of JPEG that OpenCV '
                             'cannot decode')
        return bgr


def _fourcc_text(code: float) -> str:
    value = int(code) if math.isfinite(code) and code > 0 else 0
    text = value.to_bytes(4, 'little').decode('ascii', errors='replace')
    return text if value and text.isprintable() else ''


class VideoSource:
    """An open camera or video file; `read` hands out `Frame` objects.

    Parameters
    ----------
    settings : CaptureSettings
    clock : callable
        Called right after each grab for the frame's ``stamp`` (default ``time.time``).
    sleep : callable
        ``sleep(seconds)`` used to pace a file (default ``time.sleep``; a
        ``threading.Event().wait`` lets a stop request cut it short).

    Raises
    ------
    CaptureError
        The source is not there or OpenCV cannot open it.

    Attributes
    ----------
    width, height : int
        Image size the source reports [px].
    fps : float
        Frame rate the device reports, or the pace of a file [Hz] (0 when unknown).
    fourcc : str
        The source's pixel format or codec as OpenCV reports it (``'MJPG'``), '' if none.
    passthrough : bool
        Whether frames come as the source's JPEG bytes (as far as known: pass-through is
        switched off at the first packet that is not a JPEG).
    loops : int
        Times a file restarted at its end.
    """

    def __init__(self, settings: CaptureSettings, clock: Callable[[], object] = time.time,
                 sleep: Callable[[float], object] = time.sleep) -> None:
        self.settings = settings
        self.clock = clock
        self.sleep = sleep
        self.passthrough = settings.jpeg_passthrough
        self.loops = 0
        self._index = 0
        self._position = 0  # frames read from the file since it was (re)opened
        self._failures = 0
        self._ended = False
        self._due: float | None = None
        self._cap: cv2.VideoCapture | None = None
        self._open()

    # -- opening -------------------------------------------------------------------------------

    @property
    def is_file(self) -> bool:
        return self.settings.kind == 'file'

    def _error(self, message: str) -> CaptureError:
        return CaptureError(self.settings.device, message)

    def _open(self) -> None:
        self.close()
        s = self.settings
        kind = s.kind
        if kind == 'file':
            if not os.path.isfile(s.device):
                raise self._error('no such file' if not os.path.exists(s.device)
                                  else 'not a file')
            cap = cv2.VideoCapture(s.device, cv2.CAP_FFMPEG)
            if not cap.isOpened():
                cap.release()
                raise self._error("OpenCV's FFmpeg backend cannot open it as a video")
        else:
            linux = sys.platform.startswith('linux')
            target = int(s.device) if kind == 'index' else s.device.strip()
            path = f'/dev/video{target}' if kind == 'index' else target
            if linux and not os.path.exists(path):
                raise self._error(f'no such device ({path} does not exist)')
            cap = cv2.VideoCapture(target, cv2.CAP_V4L2 if linux else cv2.CAP_ANY)
            if not cap.isOpened():
                cap.release()
                raise self._error('OpenCV cannot open it as a camera')
            if s.fourcc:
                cap.set(cv2.CAP_PROP_FOURCC, cv2.VideoWriter_fourcc(*s.fourcc))
            if s.width:
                cap.set(cv2.CAP_PROP_FRAME_WIDTH, s.width)
            if s.height:
                cap.set(cv2.CAP_PROP_FRAME_HEIGHT, s.height)
            if s.fps:
                cap.set(cv2.CAP_PROP_FPS, s.fps)
        if self.passthrough:
            if kind == 'file':
                cap.set(cv2.CAP_PROP_FORMAT, -1)  # FFmpeg: the encoded packets
            else:
                cap.set(cv2.CAP_PROP_CONVERT_RGB, 0)  # V4L2: the driver's buffers
        self._cap = cap
        self._position = 0
        self.width = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH))
        self.height = int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
        self.fourcc = _fourcc_text(cap.get(cv2.CAP_PROP_FOURCC))
        reported = cap.get(cv2.CAP_PROP_FPS)
        reported = reported if math.isfinite(reported) and reported > 0 else 0.0
        if kind == 'file':
            self.fps = s.fps or reported or DEFAULT_FILE_FPS
        else:
            self.fps = reported

    def close(self) -> None:
        """Release the source (idempotent)."""
        if self._cap is not None:
            self._cap.release()
            self._cap = None

    def __enter__(self) -> 'VideoSource':
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- reading -------------------------------------------------------------------------------

    def _pace(self) -> None:
        if not (self.is_file and self.settings.pace):
            return
        period = 1.0 / self.fps
        now = time.monotonic()
        if self._due is None or now - self._due > period:
            self._due = now  # first frame, or late by more than a frame: no burst to catch up
        elif self._due > now:
            self.sleep(self._due - now)
        self._due += period

    def _grab(self) -> tuple[bool, object]:
        """Grab the next frame (restarting a looping file); ``(grabbed, stamp)``."""
        if self._cap.grab():
            return True, self.clock()
        if not self.is_file:
            return False, None
        if not self.settings.loop:
            self._ended = True
            return False, None
        empty = self._position == 0
        self._open()
        if empty or not self._cap.grab():
            raise self._error('no frame could be read from the file')
        self.loops += 1
        return True, self.clock()

    def read(self) -> Frame | None:
        """The next frame; None at the end of a file that does not loop (and after it).

        A file is paced to ``fps`` first (``sleep``); the stamp is taken right after the grab.

        Raises
        ------
        CaptureError
            A device failed `MAX_READ_FAILURES` times in a row (it is probably gone: close and
            reopen it), or a file has no frame.
        """
        if self._cap is None:
            raise self._error('closed')
        if self._ended:
            return None
        self._pace()
        while True:
            grabbed, stamp = self._grab()
            if grabbed:
                ok, data = self._cap.retrieve()
                grabbed = bool(ok) and data is not None and data.size > 0
            if not grabbed:
                if self._ended:
                    return None
                self._failures += 1
                if self._failures >= MAX_READ_FAILURES:
                    self._failures = 0
                    raise self._error(f'no frame in {MAX_READ_FAILURES} reads in a row')
                continue
            self._failures = 0
            self._position += 1
            frame = self._frame(data, stamp)
            if frame is not None:
                self._index += 1
                return frame

    def _frame(self, data: np.ndarray, stamp: object) -> Frame | None:
        """A frame from what ``retrieve`` returned; None if pass-through had to be switched off
        (the source was reopened and positioned at this frame again)."""
        if self.passthrough:
            jpeg = data.reshape(-1).tobytes()
            try:
                width, height = jpeg_size(jpeg)
            except ValueError:
                self._decode_from_now_on()
                return None
            return Frame(self._index, stamp, width, height, jpeg=jpeg)
        bgr = data
        if bgr.ndim == 2:
            bgr = cv2.cvtColor(bgr, cv2.COLOR_GRAY2BGR)
        elif bgr.ndim != 3 or bgr.shape[2] != 3 or bgr.dtype != np.uint8:
            raise self._error(f'unexpected frame of {bgr.dtype} {bgr.shape} (expected 8-bit BGR)')
        return Frame(self._index, stamp, bgr.shape[1], bgr.shape[0], bgr=bgr)

    def _decode_from_now_on(self) -> None:
        position = self._position - 1
        self.passthrough = False
        self._open()
        if self.is_file and position > 0:
            self._cap.set(cv2.CAP_PROP_POS_FRAMES, position)
            self._position = position
