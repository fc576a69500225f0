"""Where rosdep finds each dependency key that a package.xml declares, other than the workspace's
own packages (``tests/test_package_manifests.py`` checks every key against this table).

Read from ros/rosdistro at commit ``ROSDISTRO_COMMIT``. A ROS package resolves through
``jazzy/distribution.yaml``: the second field names the repository that releases it (installed
as ``ros-jazzy-<name>``). Any other key is a rule in ``rosdep/python.yaml`` or
``rosdep/base.yaml``: the second field is the rule's ``ubuntu`` entry. A list (or ``'*'``)
rather than release names covers every Ubuntu release, noble (Jazzy's) included; ``pip``
installs from PyPI. Keys of PyPI-only packages end in ``-pip``. cobs has only a key of the
Python 2 era's name, ``python-cobs-pip``: a name, whose rule is ``pip install cobs`` with the
pip of ROS's Python.

To compare the table with a rosdistro checkout:
``ROSDISTRO_DIR=<checkout> python -m pytest tests/test_package_manifests.py -k rosdistro``.
"""

ROSDISTRO_COMMIT = '8468e88ccd523427f9131e39d2af0938f1c298b2'  # 2026-08-22

DISTRIBUTION = 'jazzy/distribution.yaml'
PYTHON = 'rosdep/python.yaml'
BASE = 'rosdep/base.yaml'

# key -> (file of rosdistro that defines it, its repository or its ubuntu entry there)
ROSDEP_SOURCES = {
    'ament_index_python': (DISTRIBUTION, 'ament_index'),
    'builtin_interfaces': (DISTRIBUTION, 'rcl_interfaces'),
    'diagnostic_msgs': (DISTRIBUTION, 'common_interfaces'),
    'geometry_msgs': (DISTRIBUTION, 'common_interfaces'),
    'launch': (DISTRIBUTION, 'launch'),
    'launch_ros': (DISTRIBUTION, 'launch_ros'),
    'lifecycle_msgs': (DISTRIBUTION, 'rcl_interfaces'),
    'nav_msgs': (DISTRIBUTION, 'common_interfaces'),
    'pinocchio': (DISTRIBUTION, 'pinocchio'),
    'rcl_interfaces': (DISTRIBUTION, 'rcl_interfaces'),
    'rclpy': (DISTRIBUTION, 'rclpy'),
    'robot_state_publisher': (DISTRIBUTION, 'robot_state_publisher'),
    'rosgraph_msgs': (DISTRIBUTION, 'rcl_interfaces'),
    'rviz2': (DISTRIBUTION, 'rviz'),
    'sensor_msgs': (DISTRIBUTION, 'common_interfaces'),
    'std_msgs': (DISTRIBUTION, 'common_interfaces'),
    'std_srvs': (DISTRIBUTION, 'common_interfaces'),
    'tf2_ros': (DISTRIBUTION, 'geometry2'),
    'visualization_msgs': (DISTRIBUTION, 'common_interfaces'),
    'python-cobs-pip': (PYTHON, {'pip': {'packages': ['cobs']}}),
    'python3-catkin-pkg': (PYTHON, ['python3-catkin-pkg']),
    'python3-hypothesis': (PYTHON, ['python3-hypothesis']),
    'python3-jsonschema': (PYTHON, ['python3-jsonschema']),
    'python3-matplotlib': (PYTHON, ['python3-matplotlib']),
    'python3-numba': (PYTHON, ['python3-numba']),
    'python3-numpy': (PYTHON, ['python3-numpy']),
    'python3-opencv': (PYTHON, ['python3-opencv']),
    'python3-pil': (PYTHON, ['python3-pil']),
    'python3-pytest': (PYTHON, ['python3-pytest']),
    'python3-pytest-timeout': (PYTHON, ['python3-pytest-timeout']),
    'python3-rosbags-pip': (PYTHON, {'pip': {'packages': ['rosbags']}}),
    'python3-scipy': (PYTHON, ['python3-scipy']),
    'python3-serial': (PYTHON, ['python3-serial']),
    'python3-skimage': (PYTHON, ['python3-skimage']),
    'python3-tqdm': (PYTHON, {'*': ['python3-tqdm']}),
    'python3-yaml': (PYTHON, ['python3-yaml']),
    'chromium-browser': (BASE, ['chromium-browser']),
    'iproute2': (BASE, ['iproute2']),
}
