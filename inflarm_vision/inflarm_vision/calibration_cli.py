"""``inflarm-calibrate-camera``: a camera's intrinsics from checkerboard images, its pose in
``sra_mount`` from images of the ball at known positions.

Usage::

    inflarm-calibrate-camera intrinsics IMAGES... --board COLSxROWS --square-m 0.025 \\
        --out camera.yaml [--camera-name NAME] [--min-images 3] [--k-coefficients 2]
    inflarm-calibrate-camera extrinsics POINTS.csv --camera-info camera.yaml \\
        --out ball_tracker_camera.yaml [--ball-diameter-m 0.04]
    inflarm-calibrate-camera synthetic DIR [--seed 7] [--images 15]

``intrinsics`` writes the calibration in the YAML format of ROS's
``camera_calibration_parsers`` (for the camera driver's ``camera_info_url``) and prints the RMS
reprojection error and the images used. ``--board`` counts the **inner** corners.

``extrinsics`` reads a CSV with the header ``image,x_m,y_m,z_m``: per row an image of the ball
and the ball centre's known position in ``sra_mount`` [m] (image paths relative to the CSV's
folder), at least 4 rows not on one line. It detects and locates the ball in each image with
the intrinsics of ``--camera-info`` and writes the pose as a ``ball_tracker`` parameters file
(``--ros-args --params-file``).

``synthetic`` writes an example to try both on (DIR must not exist or be empty): checkerboard
images (``DIR/intrinsics/``) and ball images with ``points.csv`` (``DIR/extrinsics/``) rendered
through a known camera with ``plumb_bob`` distortion, and the true answers
(``DIR/truth_camera.yaml``, ``DIR/truth_ball_tracker_camera.yaml``).

Exit status: 0 on success, 2 on bad arguments or bad input (the reason on stderr).
"""

import argparse
from collections.abc import Sequence
import csv
import math
import os
import re
import sys

import cv2
import numpy as np

from inflarm_model.camera import PinholeCamera, look_at
from inflarm_msgs_json.cli import positive_float
from inflarm_vision.calibration import (
    CameraIntrinsics,
    CheckerboardRenderer,
    calibrate_extrinsics,
    calibrate_intrinsics,
    random_board_poses,
    read_camera_info_yaml,
    render_ball,
    write_ball_tracker_params,
    write_camera_info_yaml,
)

PROG = 'inflarm-calibrate-camera'
POINTS_HEADER = ('image', 'x_m', 'y_m', 'z_m')
DEFAULT_SEED = 7

# The example's camera: sra_sim's image size, focal length and distortion, the principal point
# off the image centre; looking at the work space from 1 m.
EXAMPLE_CAMERA = PinholeCamera(
    640, 480, np.array([[900.0, 0.0, 331.7], [0.0, 900.0, 231.2], [0.0, 0.0, 1.0]]),
    np.array([-0.12, 0.05, 0.0, 0.0, 0.0]))
EXAMPLE_CAMERA2MOUNT = look_at([0.15, -1.0, 0.85], [0.0, 0.0, 0.75])
EXAMPLE_BOARD = (9, 6)
EXAMPLE_SQUARE_M = 0.025
EXAMPLE_BALL_DIAMETER_M = 0.04
# corners of a box in the work space and its centre [m, sra_mount]
EXAMPLE_BALL_POSITIONS = np.array(
    [[x, y, z] for x in (-0.15, 0.15) for y in (-0.15, 0.15) for z in (0.6, 0.95)]
    + [[0.0, 0.0, 0.78]])


class _InputError(Exception):
    """Bad input: the message goes to stderr, the exit status is 2."""


def _board(text: str) -> tuple[int, int]:
    match = re.fullmatch(r'\s*(\d+)\s*[xX]\s*(\d+)\s*', text)
    if not match:
        raise argparse.ArgumentTypeError(f'expected COLSxROWS inner corners (e.g. 9x6), got '
                                         f'{text!r}')
    return int(match.group(1)), int(match.group(2))


def build_parser() -> argparse.ArgumentParser:
    """Command-line parser of ``inflarm-calibrate-camera``."""
    parser = argparse.ArgumentParser(
        prog=PROG, description='Calibrate a camera: intrinsics from checkerboard images, the '
                               'pose in sra_mount from images of the ball at known positions.')
    sub = parser.add_subparsers(dest='command', required=True, metavar='COMMAND')

    intr = sub.add_parser('intrinsics', help='camera matrix and distortion from checkerboard '
                                             'images')
    intr.add_argument('images', nargs='+', metavar='IMAGE', help='images of the board')
    intr.add_argument('--board', type=_board, required=True, metavar='COLSxROWS',
                      help='inner corners of the board along x across, e.g. 9x6 for a board '
                           'of 10 x 7 squares')
    intr.add_argument('--square-m', type=positive_float, required=True,
                      help='side of a square [m]')
    intr.add_argument('--out', required=True, metavar='YAML',
                      help='calibration file to write (camera_calibration_parsers format)')
    intr.add_argument('--camera-name', default='camera', help='camera_name (default: camera)')
    intr.add_argument('--min-images', type=int, default=3,
                      help='fewest images the board must be found in (default: 3)')
    intr.add_argument('--k-coefficients', type=int, choices=(2, 3), default=2,
                      help='radial distortion coefficients fitted (default: 2, k3 = 0)')

    extr = sub.add_parser('extrinsics', help='camera pose in sra_mount from ball images')
    extr.add_argument('points', metavar='POINTS.csv',
                      help='CSV with the header ' + ','.join(POINTS_HEADER)
                           + ': image path (relative to the CSV), ball centre in sra_mount [m]')
    extr.add_argument('--camera-info', required=True, metavar='YAML',
                      help="the camera's intrinsics (from the intrinsics command)")
    extr.add_argument('--out', required=True, metavar='YAML',
                      help='ball_tracker parameters file to write')
    extr.add_argument('--ball-diameter-m', type=positive_float, default=0.04,
                      help='diameter of the ball [m] (default: 0.04)')

    synth = sub.add_parser('synthetic', help='write a synthetic example to try the commands on')
    synth.add_argument('dir', metavar='DIR', help='folder to write (must not exist or be empty)')
    synth.add_argument('--seed', type=int, default=DEFAULT_SEED,
                       help=f'seed of the poses and the noise (default: {DEFAULT_SEED})')
    synth.add_argument('--images', type=int, default=15,
                       help='number of checkerboard images (default: 15)')
    return parser


def _read_image(path: str, flags: int) -> np.ndarray:
    image = cv2.imread(path, flags)
    if image is None:
        raise _InputError(f'cannot read image {path} (missing, or not an image file)')
    return image


def run_intrinsics(args: argparse.Namespace) -> None:
    images = []
    for path in args.images:
        image = _read_image(path, cv2.IMREAD_GRAYSCALE)
        if images and image.shape != images[0].shape:
            raise _InputError(f'{path}: {image.shape[1]}x{image.shape[0]} px, but '
                           f'{args.images[0]} is {images[0].shape[1]}x{images[0].shape[0]} px: '
                           f'all images must come from the same camera mode')
        images.append(image)
    calibration = calibrate_intrinsics(images, args.board, args.square_m,
                                       camera_name=args.camera_name,
                                       min_images=args.min_images,
                                       k_coefficients=args.k_coefficients)
    write_camera_info_yaml(calibration, args.out)
    cols, rows = args.board
    print(f'board {cols}x{rows} found in {len(calibration.used_images)} of {len(images)} '
          f'images:')
    for index, rms in zip(calibration.used_images, calibration.per_image_rms_px, strict=True):
        print(f'  {args.images[index]}  RMS {rms:.3f} px')
    unused = sorted(set(range(len(images))) - set(calibration.used_images))
    if unused:
        print('not found in: ' + ', '.join(args.images[i] for i in unused))
    k, d = calibration.camera_matrix, calibration.distortion
    print(f'RMS reprojection error {calibration.rms_px:.3f} px')
    std = calibration.intrinsics_std
    print('  '.join(f'{name} {value:.2f} +- {sd:.2f}' for name, value, sd in zip(
        ('fx', 'fy', 'cx', 'cy'), (k[0, 0], k[1, 1], k[0, 2], k[1, 2]), std, strict=False))
        + ' [px] (+- one standard deviation)')
    print('distortion plumb_bob  ' + '  '.join(
        f'{name} {value:.5f}' for name, value in zip(('k1', 'k2', 'p1', 'p2', 'k3'), d,
                                                     strict=True)))
    print(f'wrote {args.out}')


def _read_points(path: str) -> tuple[list[str], list[str], np.ndarray]:
    """Image names as written, their paths, and the ball positions of a points CSV."""
    folder = os.path.dirname(os.path.abspath(path))
    with open(path, newline='', encoding='utf-8') as handle:
        rows = [row for row in csv.reader(handle) if row and not row[0].startswith('#')]
    if not rows or tuple(cell.strip() for cell in rows[0]) != POINTS_HEADER:
        raise _InputError(f'{path}: expected the header {",".join(POINTS_HEADER)}, got '
                       f'{",".join(rows[0]) if rows else "an empty file"}')
    names, images, points = [], [], []
    for line, row in enumerate(rows[1:], start=2):
        if len(row) != 4:
            raise _InputError(f'{path} row {line}: expected 4 values, got {len(row)}')
        try:
            xyz = [float(cell) for cell in row[1:]]
        except ValueError:
            raise _InputError(f'{path} row {line}: expected x_m, y_m, z_m numbers, got '
                           f'{row[1:]}') from None
        if not all(math.isfinite(x) for x in xyz):
            raise _InputError(f'{path} row {line}: expected finite x_m, y_m, z_m, got {row[1:]}')
        names.append(row[0].strip())
        images.append(os.path.join(folder, names[-1]))
        points.append(xyz)
    if len(points) < 4:
        raise _InputError(f'{path}: expected at least 4 ball positions, got {len(points)}')
    return names, images, np.array(points)


def run_extrinsics(args: argparse.Namespace) -> None:
    camera = read_camera_info_yaml(args.camera_info).pinhole_camera()
    names, paths, points_mount = _read_points(args.points)
    images = [_read_image(path, cv2.IMREAD_COLOR) for path in paths]
    try:
        result = calibrate_extrinsics(points_mount, images, camera, args.ball_diameter_m)
    except ValueError as err:  # name the image file rather than its index
        text = re.sub(r'^image (\d+):', lambda m: f'{paths[int(m.group(1))]}:', str(err))
        raise _InputError(text) from None
    write_ball_tracker_params(result, args.out)
    pose = result.camera2mount
    print(f'{len(paths)} ball positions; residual per point [mm]:')
    for name, residual in zip(names, result.residuals, strict=True):
        print(f'  {name}  {1e3 * residual:.2f}')
    print(f'RMS residual {1e3 * result.rms:.2f} mm')
    print('camera.translation_m: [' + ', '.join(f'{x:.4f}' for x in pose.translation) + ']')
    print('camera.rotation_xyzw: [' + ', '.join(f'{x:.5f}' for x in pose.as_quaternion())
          + ']')
    print(f'wrote {args.out}')


def run_synthetic(args: argparse.Namespace) -> None:
    if args.images < 3:
        raise _InputError(f'expected --images >= 3, got {args.images}')
    if os.path.exists(args.dir) and (not os.path.isdir(args.dir) or os.listdir(args.dir)):
        raise _InputError(f'{args.dir} exists and is not an empty folder; synthetic will not '
                       f'overwrite it')
    rng = np.random.default_rng(args.seed)
    camera = EXAMPLE_CAMERA
    intrinsics_dir = os.path.join(args.dir, 'intrinsics')
    extrinsics_dir = os.path.join(args.dir, 'extrinsics')
    os.makedirs(intrinsics_dir)
    os.makedirs(extrinsics_dir)
    renderer = CheckerboardRenderer(camera, EXAMPLE_BOARD, EXAMPLE_SQUARE_M)
    poses = random_board_poses(camera, EXAMPLE_BOARD, EXAMPLE_SQUARE_M, args.images, rng)
    for index, pose in enumerate(poses):
        image = renderer.render(pose, noise_std=1.0, rng=rng)
        cv2.imwrite(os.path.join(intrinsics_dir, f'board_{index:02d}.png'), image)
    mount2camera = EXAMPLE_CAMERA2MOUNT.inverse()
    with open(os.path.join(extrinsics_dir, 'points.csv'), 'w', newline='',
              encoding='utf-8') as handle:
        writer = csv.writer(handle)
        writer.writerow(POINTS_HEADER)
        for index, point in enumerate(EXAMPLE_BALL_POSITIONS):
            name = f'ball_{index:02d}.png'
            image = render_ball(camera, mount2camera.apply(point), 0.5 * EXAMPLE_BALL_DIAMETER_M,
                                noise_std=1.0, rng=rng)
            cv2.imwrite(os.path.join(extrinsics_dir, name), image)
            writer.writerow([name, *(repr(float(x)) for x in point)])
    write_camera_info_yaml(CameraIntrinsics.from_pinhole_camera(camera),
                           os.path.join(args.dir, 'truth_camera.yaml'))
    write_ball_tracker_params(EXAMPLE_CAMERA2MOUNT,
                              os.path.join(args.dir, 'truth_ball_tracker_camera.yaml'))
    board = f'{EXAMPLE_BOARD[0]}x{EXAMPLE_BOARD[1]}'
    d = args.dir
    print(f'wrote {len(poses)} checkerboard images ({board} inner corners, '
          f'{EXAMPLE_SQUARE_M} m squares) to {intrinsics_dir}')
    print(f'wrote {len(EXAMPLE_BALL_POSITIONS)} ball images and points.csv to {extrinsics_dir}')
    print('try:')
    print(f'  {PROG} intrinsics {os.path.join(d, "intrinsics", "*.png")} --board {board} '
          f'--square-m {EXAMPLE_SQUARE_M} --out {os.path.join(d, "camera.yaml")}')
    print(f'  {PROG} extrinsics {os.path.join(d, "extrinsics", "points.csv")} --camera-info '
          f'{os.path.join(d, "camera.yaml")} --out '
          f'{os.path.join(d, "ball_tracker_camera.yaml")}')
    print(f'and compare with {os.path.join(d, "truth_camera.yaml")} and '
          f'{os.path.join(d, "truth_ball_tracker_camera.yaml")}')


_COMMANDS = {'intrinsics': run_intrinsics, 'extrinsics': run_extrinsics,
             'synthetic': run_synthetic}


def main(argv: Sequence[str] | None = None) -> int:
    """Run the tool; returns the exit status (0 ok, 2 bad arguments or bad input)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse exits on --help and usage errors
        return int(exc.code) if isinstance(exc.code, int) else 2
    try:
        _COMMANDS[args.command](args)
    except (_InputError, OSError, ValueError, cv2.error) as exc:
        print(f'{PROG}: error: {exc}', file=sys.stderr)
        return 2
    return 0


if __name__ == '__main__':
    sys.exit(main())
