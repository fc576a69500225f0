"""The capture core on real OpenCV: MJPG AVI files written by cv2.VideoWriter read back frame by
frame, as decoded images and as the file's own JPEG packets; looping, pacing, a non-JPEG codec,
and the errors for sources that are not there and for bad settings. No ROS."""

import time

import cv2
import numpy as np
import pytest

from inflarm_vision.capture import (
    JPEG_SIGNATURE,
    CaptureError,
    CaptureSettings,
    VideoSource,
    jpeg_size,
    source_kind,
)

WIDTH, HEIGHT, FRAMES, FILE_FPS = 160, 120, 6, 10.0


def write_video(path, frames, fourcc='MJPG', fps=FILE_FPS) -> None:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), fps,
                             (frames[0].shape[1], frames[0].shape[0]))
    assert writer.isOpened(), f'OpenCV cannot write {fourcc}'
    for frame in frames:
        writer.write(frame)
    writer.release()


def distinct_frames(count=FRAMES, seed=7) -> list[np.ndarray]:
    """Frames of one colour each (well apart) with the frame number written on."""
    rng = np.random.default_rng(seed)
    frames = []
    for k in range(count):
        frame = np.empty((HEIGHT, WIDTH, 3), np.uint8)
        frame[:] = rng.integers(0, 256, 3)
        frame[:, :, k % 3] = 40 * k  # no two frames alike
        cv2.putText(frame, str(k), (50, 90), cv2.FONT_HERSHEY_SIMPLEX, 2.5, (255, 255, 255), 4)
        frames.append(frame)
    return frames


def which(image: np.ndarray, frames: list[np.ndarray]) -> int:
    """The written frame an image is closest to."""
    return int(np.argmin([np.abs(image.astype(float) - f).mean() for f in frames]))


@pytest.fixture(scope='module')
def video(tmp_path_factory):
    frames = distinct_frames()
    path = tmp_path_factory.mktemp('capture') / 'frames.avi'
    write_video(path, frames)
    return path, frames


def fast(path, **kwargs) -> VideoSource:
    return VideoSource(CaptureSettings(str(path), pace=False, **kwargs))


def test_a_file_is_read_back_frame_by_frame(video):
    path, frames = video
    with fast(path, loop=False) as source:
        assert (source.width, source.height, source.fourcc) == (WIDTH, HEIGHT, 'MJPG')
        assert source.fps == FILE_FPS  # fps 0: the file's rate
        assert not source.passthrough
        read = [source.read() for _ in range(FRAMES)]
        assert source.read() is None and source.read() is None  # the end, for good
    for k, frame in enumerate(read):
        assert frame.index == k and frame.jpeg is None
        assert frame.bgr.shape == (HEIGHT, WIDTH, 3) and frame.bgr.dtype == np.uint8
        assert (frame.width, frame.height) == (WIDTH, HEIGHT)
        assert which(frame.bgr, frames) == k
        # JPEG at OpenCV's default quality: about 1 grey level off on average here
        assert np.abs(frame.bgr.astype(float) - frames[k]).mean() < 4.0


def test_jpeg_packets_are_the_files_jpegs_and_decode_to_the_written_frames(video):
    path, frames = video
    with fast(path, loop=False, jpeg_passthrough=True) as source:
        read = [source.read() for _ in range(FRAMES)]
        assert source.passthrough and source.read() is None
    with fast(path, loop=False) as decoded_source:
        decoded = [decoded_source.read().bgr for _ in range(FRAMES)]
    assert len({f.jpeg for f in read}) == FRAMES
    for k, frame in enumerate(read):
        assert frame.bgr is None
        assert frame.jpeg.startswith(JPEG_SIGNATURE) and frame.jpeg.endswith(b'\xff\xd9')
        assert jpeg_size(frame.jpeg) == (frame.width, frame.height) == (WIDTH, HEIGHT)
        image = frame.image()
        assert which(image, frames) == k
        assert np.abs(image.astype(float) - frames[k]).mean() < 4.0
        # the same JPEG as FFmpeg decodes it (another decoder: chroma upsampling differs)
        assert np.abs(image.astype(float) - decoded[k]).mean() < 3.0
    # the bytes are the file's: the MJPG AVI holds each one verbatim
    data = path.read_bytes()
    assert all(frame.jpeg in data for frame in read)


def test_a_looping_file_starts_again_with_the_same_packets(video):
    path, frames = video
    with fast(path, jpeg_passthrough=True) as source:
        read = [source.read() for _ in range(2 * FRAMES + 3)]
        assert source.loops == 2
    assert [f.index for f in read] == list(range(2 * FRAMES + 3))
    assert [f.jpeg for f in read] == [f.jpeg for f in read[:FRAMES]] * 2 + [
        f.jpeg for f in read[:3]]
    with fast(path) as source:
        order = [which(source.read().bgr, frames) for _ in range(FRAMES + 2)]
    assert order == [*range(FRAMES), 0, 1]


def test_a_file_is_paced_to_fps_and_stamped_after_each_grab(video):
    path, _ = video
    ticks = iter(range(1000))
    sleeps: list[float] = []

    def sleep(seconds: float) -> None:
        sleeps.append(seconds)
        time.sleep(seconds)

    with VideoSource(CaptureSettings(str(path), fps=40.0), clock=lambda: next(ticks),
                     sleep=sleep) as source:
        assert source.fps == 40.0
        start = time.monotonic()
        read = [source.read() for _ in range(9)]
        elapsed = time.monotonic() - start
    assert [f.stamp for f in read] == list(range(9))  # one clock() per frame
    # 8 periods of 25 ms at least (the schedule never runs ahead; a loaded machine may lag)
    assert elapsed >= 8 * 0.025 * 0.95, elapsed
    assert sleeps and all(0.0 < s <= 0.025 + 1e-9 for s in sleeps), sleeps
    with fast(path, fps=40.0) as source:  # pace False: as fast as the file reads
        source.sleep = lambda s: pytest.fail('slept without pacing')
        [source.read() for _ in range(9)]


def test_a_file_of_another_codec_falls_back_to_decoded_frames(tmp_path):
    frames = distinct_frames(4, seed=11)
    path = tmp_path / 'frames.mp4'
    write_video(path, frames, fourcc='mp4v')
    with fast(path, loop=False, jpeg_passthrough=True) as source:
        read = [source.read() for _ in range(4)]
        assert not source.passthrough and source.read() is None
    assert [f.index for f in read] == [0, 1, 2, 3]
    assert all(f.jpeg is None and f.bgr.shape == (HEIGHT, WIDTH, 3) for f in read)
    assert [which(f.bgr, frames) for f in read] == [0, 1, 2, 3]  # frame 0 not lost


def test_a_source_that_is_not_there_or_not_a_video_is_a_capture_error(tmp_path):
    with pytest.raises(CaptureError, match=r"video source '.*missing.avi': no such file"):
        VideoSource(CaptureSettings(str(tmp_path / 'missing.avi')))
    garbage = tmp_path / 'garbage.avi'
    garbage.write_bytes(b'not a video at all' * 100)
    with pytest.raises(CaptureError, match='cannot open it as a video'):
        VideoSource(CaptureSettings(str(garbage)))
    with pytest.raises(CaptureError, match='not a file'):
        VideoSource(CaptureSettings(str(tmp_path)))
    with pytest.raises(CaptureError, match=r"'/dev/video_missing': no such device"):
        VideoSource(CaptureSettings('/dev/video_missing'))
    with pytest.raises(CaptureError, match=r"'97': no such device \(/dev/video97"):
        VideoSource(CaptureSettings('97'))
    error = pytest.raises(CaptureError, VideoSource, CaptureSettings('97')).value
    assert isinstance(error, ValueError) and error.source == '97'


def test_a_file_with_no_frame_that_loops_is_a_capture_error(tmp_path):
    path = tmp_path / 'empty.avi'
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*'MJPG'), 10.0, (64, 48))
    writer.release()
    try:
        source = fast(path)
    except CaptureError:
        return  # OpenCV refuses to open it at all: as good
    with source, pytest.raises(CaptureError, match='no frame could be read'):
        source.read()


@pytest.mark.parametrize(('settings', 'match'), [
    (dict(fourcc='MJPEG'), "expected a fourcc of 4 ASCII characters.*got 'MJPEG'"),
    (dict(fourcc='MJP'), "got 'MJP'"),
    (dict(fourcc='MJ\u00e9G'), 'fourcc of 4 ASCII'),
    (dict(width=-1), 'expected width an integer in 0-16384'),
    (dict(height=1.5), 'expected height an integer'),
    (dict(fps=float('nan')), 'expected fps in 0-1000 Hz'),
    (dict(fps=-1.0), 'expected fps'),
    (dict(device=' '), 'expected a device'),
])
def test_bad_settings_are_refused(settings, match):
    with pytest.raises(ValueError, match=match):
        CaptureSettings(**{'device': '/dev/video0', **settings})


def test_sources_are_told_apart_and_jpeg_sizes_read_from_the_header():
    assert [source_kind(d) for d in ('0', '12', '/dev/video0', 'a.avi', '/data/0.avi')] == [
        'index', 'index', 'device', 'file', 'file']
    image = np.random.default_rng(7).integers(0, 256, (21, 37, 3), dtype=np.uint8)
    for quality in (50, 95):
        ok, jpeg = cv2.imencode('.jpg', image, [cv2.IMWRITE_JPEG_QUALITY, quality])
        assert ok and jpeg_size(jpeg.tobytes()) == (37, 21)
    ok, png = cv2.imencode('.png', image)
    with pytest.raises(ValueError, match='not a JPEG'):
        jpeg_size(png.tobytes())
    with pytest.raises(ValueError, match='without a frame header'):
        jpeg_size(JPEG_SIGNATURE + b'\xd9')
