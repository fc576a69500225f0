"""inflarm_vision.calibration and inflarm-calibrate-camera: intrinsics recovered from rendered
checkerboards, the camera_calibration_parsers YAML round trip and its bad inputs, the camera's
pose from ball positions written as ball_tracker parameters, and the CLI end to end."""

import glob
import math
import os
import subprocess
import sys

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation
import yaml

from inflarm_model.camera import PinholeCamera, RigidTransform, look_at, project_points
from inflarm_vision.calibration import (
    CameraIntrinsics,
    CheckerboardRenderer,
    board_corners,
    calibrate_extrinsics,
    calibrate_intrinsics,
    camera_info_yaml,
    random_board_poses,
    read_camera_info_yaml,
    render_ball,
    write_ball_tracker_params,
    write_camera_info_yaml,
)
from inflarm_vision.calibration_cli import (
    EXAMPLE_CAMERA,
    EXAMPLE_CAMERA2MOUNT,
    main,
)
from inflarm_vision.geometry import calibrate_camera_to_mount

BOARD = (9, 6)
SQUARE_M = 0.025
TRUE_K = np.array([[905.0, 0.0, 331.7], [0.0, 902.0, 227.4], [0.0, 0.0, 1.0]])
TRUE_D = np.array([-0.12, 0.05, 0.0, 0.0, 0.0])
CAMERA = PinholeCamera(640, 480, TRUE_K, TRUE_D)
N_VIEWS = 20


@pytest.fixture(scope='module')
def renderer():
    return CheckerboardRenderer(CAMERA, BOARD, SQUARE_M)


@pytest.fixture(scope='module')
def views(renderer):
    """(poses, images): 20 views tilted 15-45 deg, 1 grey level of noise."""
    rng = np.random.default_rng(7)
    poses = random_board_poses(CAMERA, BOARD, SQUARE_M, N_VIEWS, rng)
    return poses, [renderer.render(pose, noise_std=1.0, rng=rng) for pose in poses]


@pytest.fixture(scope='module')
def calibration(views):
    return calibrate_intrinsics(views[1], BOARD, SQUARE_M, camera_name='test_cam')


# -- the renderer ------------------------------------------------------------------------------

def test_the_rendered_board_shows_its_corners_where_the_camera_projects_them(views):
    poses, images = views
    errors = []
    for pose, image in zip(poses[:4], images[:4], strict=True):
        found, corners = cv2.findChessboardCorners(image, BOARD)
        assert found
        corners = cv2.cornerSubPix(image, corners, (5, 5), (-1, -1),
                                   (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-4))
        truth = project_points(CAMERA, pose.apply(board_corners(BOARD, SQUARE_M)))
        errors.append(corners.reshape(-1, 2) - truth)
    errors = np.concatenate(errors)
    # no offset (the pixel convention), and cornerSubPix's own scatter under perspective
    assert np.all(np.abs(errors.mean(axis=0)) < 0.02)
    distances = np.linalg.norm(errors, axis=1)
    assert np.median(distances) < 0.1 and distances.max() < 0.3


def test_board_poses_are_tilted_as_asked_and_keep_the_board_in_the_image(views):
    poses, _ = views
    tilts = [math.degrees(math.acos(pose.rotation[2, 2])) for pose in poses]
    assert min(tilts) >= 15.0 - 1e-9 and max(tilts) <= 45.0 + 1e-9


# -- intrinsics --------------------------------------------------------------------------------

def test_calibration_recovers_the_known_camera(calibration):
    c = calibration
    k = c.camera_matrix
    assert c.used_images == tuple(range(N_VIEWS))
    assert len(c.per_image_rms_px) == N_VIEWS and max(c.per_image_rms_px) < 0.3
    assert c.rms_px < 0.3
    assert k[0, 0] == pytest.approx(TRUE_K[0, 0], rel=0.005)
    assert k[1, 1] == pytest.approx(TRUE_K[1, 1], rel=0.005)
    assert np.hypot(k[0, 2] - TRUE_K[0, 2], k[1, 2] - TRUE_K[1, 2]) < 2.0
    assert abs(c.distortion[0] - TRUE_D[0]) < 0.01 and abs(c.distortion[1] - TRUE_D[1]) < 0.03
    np.testing.assert_allclose(c.distortion[2:4], 0.0, atol=1e-3)
    assert c.distortion[4] == 0.0  # k3 fixed, as ROS's default --k-coefficients 2
    # the errors agree with the standard deviations the calibration reports
    truth = [TRUE_K[0, 0], TRUE_K[1, 1], TRUE_K[0, 2], TRUE_K[1, 2], *TRUE_D]
    estimate = [k[0, 0], k[1, 1], k[0, 2], k[1, 2], *c.distortion]
    assert len(c.intrinsics_std) == 9 and c.intrinsics_std[8] == 0.0
    assert np.all(np.abs(np.subtract(estimate, truth))[:8] < 3.0 * np.array(c.intrinsics_std[:8]))
    assert c.camera_name == 'test_cam' and c.distortion_model == 'plumb_bob'
    np.testing.assert_array_equal(c.rectification_matrix, np.eye(3))
    np.testing.assert_array_equal(c.projection_matrix, np.column_stack([k, np.zeros(3)]))
    assert c.image_size == (640, 480)
    assert c.pinhole_camera().focal_px == pytest.approx(math.sqrt(k[0, 0] * k[1, 1]))


def test_three_radial_coefficients_fit_as_well(views):
    c = calibrate_intrinsics(views[1], BOARD, SQUARE_M, k_coefficients=3)
    assert c.rms_px < 0.3 and c.intrinsics_std[8] > 0.0
    assert c.camera_matrix[0, 0] == pytest.approx(TRUE_K[0, 0], rel=0.005)


def test_bgr_and_grey_images_calibrate_alike(views):
    grey = views[1][:5]
    bgr = [cv2.cvtColor(image, cv2.COLOR_GRAY2BGR) for image in grey]
    a = calibrate_intrinsics(grey, BOARD, SQUARE_M)
    b = calibrate_intrinsics(bgr, BOARD, SQUARE_M)
    # OpenCV's threaded reductions make two runs on the same corners differ by ~2e-9
    np.testing.assert_allclose(a.camera_matrix, b.camera_matrix, rtol=1e-6)


def test_images_without_the_board_are_left_out_and_too_few_boards_raise(views):
    blank = np.full((480, 640), 128, np.uint8)
    images = [blank, views[1][0], blank, views[1][1], views[1][2], blank]
    assert calibrate_intrinsics(images, BOARD, SQUARE_M).used_images == (1, 3, 4)
    with pytest.raises(ValueError, match=r'9x6 inner corners found in 2 of 5 images; at least 3'):
        calibrate_intrinsics(images[:4] + [blank], BOARD, SQUARE_M)
    with pytest.raises(ValueError, match=r'found in 3 of 6 images; at least 4'):
        calibrate_intrinsics(images, BOARD, SQUARE_M, min_images=4)
    with pytest.raises(ValueError, match=r'8x6 inner corners found in 0 of 3'):
        calibrate_intrinsics(views[1][:3], (8, 6), SQUARE_M)


@pytest.mark.parametrize(('change', 'match'), [
    ({'images': []}, 'at least one image'),
    ({'images': [np.zeros((480, 640), np.uint8), np.zeros((480, 641), np.uint8)]},
     r'image 1: expected the size of image 0, 640x480 px, got 641x480'),
    ({'images': [np.zeros((480, 640), np.float32)]}, r'image 0: expected a uint8 array'),
    ({'images': [np.zeros((480, 640, 4), np.uint8)]}, r'image 0: expected a uint8 array'),
    ({'board_size': (7, 7)}, 'cols != rows'),
    ({'board_size': (2, 5)}, r'integers >= 3'),
    ({'board_size': (9,)}, r'board_size \(cols, rows\)'),
    ({'square_m': 0.0}, r'square_m > 0'),
    ({'square_m': math.nan}, r'square_m > 0'),
    ({'min_images': 2}, r'min_images an integer >= 3'),
    ({'k_coefficients': 5}, r'k_coefficients 2 or 3'),
])
def test_bad_calibration_arguments_are_refused(change, match):
    args = {'images': [np.zeros((48, 64), np.uint8)] * 3, 'board_size': BOARD,
            'square_m': SQUARE_M}
    keywords = {k: change.pop(k) for k in ('min_images', 'k_coefficients') if k in change}
    args.update(change)
    with pytest.raises(ValueError, match=match):
        calibrate_intrinsics(args['images'], args['board_size'], args['square_m'], **keywords)


# -- the camera_calibration_parsers YAML -------------------------------------------------------

def test_the_yaml_round_trip_is_exact_and_in_the_ros_layout(calibration, tmp_path):
    path = tmp_path / 'camera.yaml'
    write_camera_info_yaml(calibration, path)
    text = path.read_text()
    assert text == camera_info_yaml(calibration)
    keys = [line.split(':')[0] for line in text.splitlines() if not line.startswith(' ')]
    assert keys == ['image_width', 'image_height', 'camera_name', 'camera_matrix',
                    'distortion_model', 'distortion_coefficients', 'rectification_matrix',
                    'projection_matrix']
    assert text.startswith('image_width: 640\nimage_height: 480\ncamera_name: test_cam\n'
                           'camera_matrix:\n  rows: 3\n  cols: 3\n  data: [')
    assert '\ndistortion_model: plumb_bob\ndistortion_coefficients:\n  rows: 1\n  cols: 5\n' \
        in text
    back = read_camera_info_yaml(path)
    for name in ('camera_matrix', 'distortion', 'rectification_matrix', 'projection_matrix'):
        np.testing.assert_array_equal(getattr(back, name), getattr(calibration, name))
    assert (back.image_size, back.camera_name, back.distortion_model) == \
        ((640, 480), 'test_cam', 'plumb_bob')
    assert back.rms_px is None and back.used_images == () and back.per_image_rms_px == ()


ROS_YAML = """\
image_width: 1280
image_height: 720
camera_name: narrow_stereo
camera_matrix:
  rows: 3
  cols: 3
  data: [ 911.49571,    0.     ,  652.58862,
            0.     ,  912.25434,  361.37766,
            0.     ,    0.     ,    1.     ]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.118851, 0.072385, -0.000262, 1e-05, 0.000000]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [ 889.6217 ,    0.     ,  652.39893,    0.     ,
            0.     ,  896.68811,  361.21398,    0.     ,
            0.     ,    0.     ,    1.     ,    0.     ]
"""


def test_a_ros_written_file_reads(tmp_path):
    # camera_calibration's layout (aligned "0." values), integers and a yaml-cpp style 1e-05
    path = tmp_path / 'ost.yaml'
    path.write_text(ROS_YAML)
    c = read_camera_info_yaml(path)
    assert c.image_size == (1280, 720) and c.camera_name == 'narrow_stereo'
    np.testing.assert_array_equal(c.camera_matrix, [[911.49571, 0.0, 652.58862],
                                                    [0.0, 912.25434, 361.37766],
                                                    [0.0, 0.0, 1.0]])
    np.testing.assert_array_equal(c.distortion, [-0.118851, 0.072385, -0.000262, 1e-05, 0.0])
    assert c.projection_matrix[0, 0] == 889.6217  # P as written, not [K | 0]
    assert c.pinhole_camera().width == 1280


def test_a_rational_polynomial_file_reads(tmp_path):
    path = tmp_path / 'rational.yaml'
    path.write_text(ROS_YAML.replace('plumb_bob', 'rational_polynomial').replace(
        'cols: 5\n  data: [-0.118851, 0.072385, -0.000262, 1e-05, 0.000000]',
        'cols: 8\n  data: [-0.1, 0.07, 0.0, 0.0, 0.01, 0.2, 0.05, 0.003]'))
    c = read_camera_info_yaml(path)
    assert c.distortion_model == 'rational_polynomial'
    np.testing.assert_array_equal(c.distortion, [-0.1, 0.07, 0.0, 0.0, 0.01, 0.2, 0.05, 0.003])


BAD_FILES = [
    ('not yaml', '{image_width: [640\n', 'not a YAML file'),
    ('a list', '- 1\n- 2\n', 'expected a mapping of calibration keys, got list'),
    ('empty', '', 'expected a mapping of calibration keys, got NoneType'),
    ('text', 'hello world\n', 'expected a mapping of calibration keys, got str'),
    ('missing keys', ROS_YAML.split('rectification_matrix')[0],
     'missing rectification_matrix, projection_matrix: not a camera calibration'),
    ('rows * cols', ROS_YAML.replace('rows: 1\n  cols: 5', 'rows: 1\n  cols: 4'),
     r'distortion_coefficients: rows \* cols = 1 \* 4 but data has 5 values'),
    ('wrong size', ROS_YAML.replace('rows: 3\n  cols: 3\n  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]',
                                    'rows: 2\n  cols: 3\n  data: [1, 0, 0, 0, 1, 0]'),
     'rectification_matrix: expected 3x3, got 2x3'),
    ('plumb_bob of 8', ROS_YAML.replace('cols: 5\n  data: [-0.118851,',
                                        'cols: 8\n  data: [0.0, 0.0, 0.0, -0.118851,'),
     r'distortion_coefficients: expected 1x5 or 5x1, got 1x8'),
    ('non-numeric', ROS_YAML.replace('0.072385', 'abc'),
     r"distortion_coefficients data\[1\]: expected a number, got 'abc'"),
    ('boolean', ROS_YAML.replace('0.072385', 'true'),
     r'distortion_coefficients data\[1\]: expected a number, got True'),
    ('nan', ROS_YAML.replace('911.49571', '.nan'),
     r'camera_matrix data\[0\]: expected a finite number, got nan'),
    ('unknown model', ROS_YAML.replace('plumb_bob', 'equidistant'),
     r"distortion_model: expected one of \['plumb_bob', 'rational_polynomial'\], got "
     r"'equidistant'"),
    ('not a camera matrix', ROS_YAML.replace('911.49571', '-911.49571'), r'expected k = '),
    ('width', ROS_YAML.replace('image_width: 1280', 'image_width: 0'),
     r'image_width: expected an integer >= 1, got 0'),
    ('height', ROS_YAML.replace('image_height: 720', 'image_height: 720.5'),
     r'image_height: expected an integer >= 1, got 720.5'),
    ('matrix not a mapping', ROS_YAML.replace('rectification_matrix:\n  rows: 3\n  cols: 3\n',
                                              'rectification_matrix: [\n'
                                              ).replace('data: [1, 0, 0, 0, 1, 0, 0, 0, 1]',
                                                        '1, 0, 0, 0, 1, 0, 0, 0, 1]'),
     'rectification_matrix: expected a mapping with rows, cols and data'),
]


@pytest.mark.parametrize(('text', 'match'), [case[1:] for case in BAD_FILES],
                         ids=[case[0] for case in BAD_FILES])
def test_a_file_that_is_not_a_calibration_is_refused_naming_it(tmp_path, text, match):
    path = tmp_path / 'bad.yaml'
    path.write_text(text)
    with pytest.raises(ValueError, match=f'^{path}: .*{match}'):
        read_camera_info_yaml(path)


def test_a_binary_file_is_refused(tmp_path):
    path = tmp_path / 'image.png'
    cv2.imwrite(str(path), np.zeros((8, 8, 3), np.uint8))
    with pytest.raises(ValueError, match=f'^{path}: not a YAML file'):
        read_camera_info_yaml(path)


def test_bad_calibration_fields_are_refused():
    with pytest.raises(ValueError, match=r'camera_matrix finite numbers of shape \(3, 3\)'):
        CameraIntrinsics(np.eye(2), TRUE_D, (640, 480))
    with pytest.raises(ValueError, match=r'expected d 5 finite coefficients'):
        CameraIntrinsics(TRUE_K, [0.1, 0.2], (640, 480))
    with pytest.raises(ValueError, match=r'image_size \(width, height\)'):
        CameraIntrinsics(TRUE_K, TRUE_D, (640, 0))
    with pytest.raises(ValueError, match=r'projection_matrix finite numbers of shape \(3, 4\)'):
        CameraIntrinsics(TRUE_K, TRUE_D, (640, 480), projection_matrix=np.eye(3))
    with pytest.raises(ValueError, match=r'rms_px None or finite >= 0'):
        CameraIntrinsics(TRUE_K, TRUE_D, (640, 480), rms_px=math.inf)


# -- extrinsics --------------------------------------------------------------------------------

CAMERA2MOUNT = look_at([0.1, -1.05, 0.8], [0.0, 0.0, 0.78])
BALL_POSITIONS = np.array([[x, y, z] for x in (-0.15, 0.15) for y in (-0.1, 0.1)
                           for z in (0.6, 0.95)])


def rotation_error_deg(a: RigidTransform, b: RigidTransform) -> float:
    return math.degrees(Rotation.from_matrix(a.rotation.T @ b.rotation).magnitude())


def test_the_pose_from_camera_frame_points_is_written_as_float_ball_tracker_parameters(tmp_path):
    rng = np.random.default_rng(7)
    points_camera = CAMERA2MOUNT.inverse().apply(BALL_POSITIONS) + rng.normal(0, 5e-4, (8, 3))
    result = calibrate_camera_to_mount(BALL_POSITIONS, points_camera)
    path = tmp_path / 'ball_tracker_camera.yaml'
    write_ball_tracker_params(result, path)
    text = path.read_text()
    assert text.startswith('# pose of the camera optical frame in sra_mount (camera2mount): '
                           '8 points, RMS residual ')
    params = yaml.safe_load(text)['ball_tracker']['ros__parameters']
    assert set(params) == {'camera.translation_m', 'camera.rotation_xyzw'}
    values = params['camera.translation_m'] + params['camera.rotation_xyzw']
    assert len(values) == 7 and all(type(x) is float for x in values)
    back = RigidTransform.from_quaternion(params['camera.translation_m'],
                                          params['camera.rotation_xyzw'])
    assert np.linalg.norm(back.translation - CAMERA2MOUNT.translation) < 2e-3
    assert rotation_error_deg(back, CAMERA2MOUNT) < 0.2
    np.testing.assert_array_equal(back.translation, result.camera2mount.translation)


def test_an_exact_pose_with_round_numbers_is_still_written_as_floats(tmp_path):
    path = tmp_path / 'identity.yaml'
    write_ball_tracker_params(RigidTransform.identity(), path, node_name='tracker_2')
    assert 'camera.translation_m: [0.0, 0.0, 0.0]\n' in path.read_text()
    params = yaml.safe_load(path.read_text())['tracker_2']['ros__parameters']
    assert params['camera.rotation_xyzw'] == [0.0, 0.0, 0.0, 1.0]
    assert all(type(x) is float for x in params['camera.rotation_xyzw'])
    with pytest.raises(ValueError, match='expected a RigidTransform camera2mount'):
        write_ball_tracker_params(np.eye(4), path)


@pytest.fixture(scope='module')
def ball_images():
    rng = np.random.default_rng(7)
    mount2camera = CAMERA2MOUNT.inverse()
    return [render_ball(CAMERA, mount2camera.apply(p), 0.02, noise_std=1.0, rng=rng)
            for p in BALL_POSITIONS]


def test_the_pose_is_recovered_from_images_of_the_ball(ball_images):
    result = calibrate_extrinsics(BALL_POSITIONS, ball_images, CAMERA, ball_diameter_m=0.04)
    assert result.rms < 1e-3
    assert np.linalg.norm(result.camera2mount.translation - CAMERA2MOUNT.translation) < 2e-3
    assert rotation_error_deg(result.camera2mount, CAMERA2MOUNT) < 0.1


def test_bad_extrinsic_input_is_refused(ball_images):
    blank = np.full_like(ball_images[0], 110)
    with pytest.raises(ValueError, match='image 2: no ball found'):
        calibrate_extrinsics(BALL_POSITIONS[:4], ball_images[:2] + [blank] + ball_images[3:4],
                             CAMERA)
    with pytest.raises(ValueError, match=r'n >= 4'):
        calibrate_extrinsics(BALL_POSITIONS[:3], ball_images[:3], CAMERA)
    with pytest.raises(ValueError, match='one image per point'):
        calibrate_extrinsics(BALL_POSITIONS, ball_images[:3], CAMERA)
    with pytest.raises(ValueError, match=r'image 0: expected 640x480 px'):
        calibrate_extrinsics(BALL_POSITIONS[:4], [blank[:240]] + ball_images[1:4], CAMERA)
    line = np.array([[0.0, 0.0, z] for z in (0.6, 0.7, 0.8, 0.9)])
    images = [render_ball(CAMERA, CAMERA2MOUNT.inverse().apply(p), 0.02) for p in line]
    with pytest.raises(ValueError, match='lie on one line'):
        calibrate_extrinsics(line, images, CAMERA)


# -- the command-line tool ---------------------------------------------------------------------

@pytest.fixture(scope='module')
def example(tmp_path_factory):
    folder = tmp_path_factory.mktemp('calibration') / 'example'
    assert main(['synthetic', str(folder)]) == 0
    return folder


def test_the_synthetic_example_calibrates_end_to_end(example, capsys):
    capsys.readouterr()
    images = sorted(glob.glob(str(example / 'intrinsics' / '*.png')))
    assert len(images) == 15
    camera_yaml = example / 'camera.yaml'
    assert main(['intrinsics', *images, '--board', '9x6', '--square-m', '0.025', '--out',
                 str(camera_yaml), '--camera-name', 'example']) == 0
    out = capsys.readouterr().out
    assert 'board 9x6 found in 15 of 15 images' in out and 'RMS reprojection error' in out
    c = read_camera_info_yaml(camera_yaml)
    assert c.camera_name == 'example'
    truth = read_camera_info_yaml(example / 'truth_camera.yaml')
    np.testing.assert_array_equal(truth.camera_matrix, EXAMPLE_CAMERA.k)
    assert c.camera_matrix[0, 0] == pytest.approx(EXAMPLE_CAMERA.k[0, 0], rel=0.005)
    assert c.camera_matrix[1, 1] == pytest.approx(EXAMPLE_CAMERA.k[1, 1], rel=0.005)
    assert np.hypot(*(c.camera_matrix[:2, 2] - EXAMPLE_CAMERA.k[:2, 2])) < 2.0

    params_yaml = example / 'ball_tracker_camera.yaml'
    assert main(['extrinsics', str(example / 'extrinsics' / 'points.csv'), '--camera-info',
                 str(camera_yaml), '--out', str(params_yaml)]) == 0
    out = capsys.readouterr().out
    assert '9 ball positions' in out and 'RMS residual' in out
    params = yaml.safe_load(params_yaml.read_text())['ball_tracker']['ros__parameters']
    pose = RigidTransform.from_quaternion(params['camera.translation_m'],
                                          params['camera.rotation_xyzw'])
    assert np.linalg.norm(pose.translation - EXAMPLE_CAMERA2MOUNT.translation) < 2e-3
    # the example's estimated principal point is 1.5 px off: that alone tilts the pose ~0.1 deg
    assert rotation_error_deg(pose, EXAMPLE_CAMERA2MOUNT) < 0.25
    truth_params = yaml.safe_load((example / 'truth_ball_tracker_camera.yaml').read_text())
    assert truth_params['ball_tracker']['ros__parameters']['camera.translation_m'] == \
        EXAMPLE_CAMERA2MOUNT.translation.tolist()


def _fails(argv, match, capsys) -> None:
    capsys.readouterr()
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert match in err, err


def test_bad_input_exits_2_with_the_reason(example, tmp_path, capsys):
    camera_yaml = str(example / 'truth_camera.yaml')
    not_image = tmp_path / 'notes.png'
    not_image.write_text('not an image')
    _fails(['intrinsics', str(not_image), '--board', '9x6', '--square-m', '0.025', '--out',
            str(tmp_path / 'c.yaml')], f'cannot read image {not_image}', capsys)
    blank = tmp_path / 'blank.png'
    cv2.imwrite(str(blank), np.full((480, 640), 128, np.uint8))
    _fails(['intrinsics', str(blank), str(blank), str(blank), '--board', '9x6', '--square-m',
            '0.025', '--out', str(tmp_path / 'c.yaml')],
           'checkerboard of 9x6 inner corners found in 0 of 3 images', capsys)
    small = tmp_path / 'small.png'
    cv2.imwrite(str(small), np.full((240, 320), 128, np.uint8))
    _fails(['intrinsics', str(blank), str(small), '--board', '9x6', '--square-m', '0.025',
            '--out', str(tmp_path / 'c.yaml')], f'{small}: 320x240 px, but {blank}', capsys)
    _fails(['intrinsics', str(blank), '--board', 'nine', '--square-m', '0.025', '--out', 'x'],
           'expected COLSxROWS inner corners', capsys)
    _fails(['intrinsics', str(blank), '--board', '9x6', '--square-m', '-1', '--out', 'x'],
           'expected a positive finite number', capsys)
    points = example / 'extrinsics' / 'points.csv'
    _fails(['extrinsics', str(points), '--camera-info', str(not_image), '--out', 'x'],
           f'{not_image}: expected a mapping of calibration keys', capsys)
    few = example / 'extrinsics' / 'few.csv'
    few.write_text(''.join(points.read_text().splitlines(keepends=True)[:4]))
    _fails(['extrinsics', str(few), '--camera-info', camera_yaml, '--out', 'x'],
           'expected at least 4 ball positions, got 3', capsys)
    header = tmp_path / 'header.csv'
    header.write_text('image,x,y,z\nball.png,0,0,1\n')
    _fails(['extrinsics', str(header), '--camera-info', camera_yaml, '--out', 'x'],
           'expected the header image,x_m,y_m,z_m', capsys)
    value = example / 'extrinsics' / 'value.csv'
    value.write_text(points.read_text().replace('0.6', 'high', 1))
    _fails(['extrinsics', str(value), '--camera-info', camera_yaml, '--out', 'x'],
           'row 2: expected x_m, y_m, z_m numbers', capsys)
    no_ball = example / 'extrinsics' / 'no_ball.csv'
    no_ball.write_text(points.read_text().replace('ball_03.png', 'blank.png'))
    cv2.imwrite(str(example / 'extrinsics' / 'blank.png'), np.full((480, 640, 3), 110, np.uint8))
    _fails(['extrinsics', str(no_ball), '--camera-info', camera_yaml, '--out', 'x'],
           f'{example / "extrinsics" / "blank.png"}: no ball found', capsys)
    _fails(['synthetic', str(example)], 'is not an empty folder', capsys)


def test_the_module_runs_as_a_program_and_exits_2_on_a_missing_file(tmp_path):
    result = subprocess.run(
        [sys.executable, '-m', 'inflarm_vision.calibration_cli', 'extrinsics',
         str(tmp_path / 'missing.csv'), '--camera-info', str(tmp_path / 'missing.yaml'),
         '--out', str(tmp_path / 'out.yaml')],
        capture_output=True, text=True, timeout=60, env={**os.environ})
    assert result.returncode == 2
    assert 'inflarm-calibrate-camera: error:' in result.stderr
    assert 'missing.yaml' in result.stderr
    assert not (tmp_path / 'out.yaml').exists()
