from glob import glob

from setuptools import find_packages, setup

package_name = 'inflarm_vision'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='inflarm developers',
    maintainer_email='dev@inflarm.org',
    description='Yellow-ball tracking in camera images.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'ball_tracker = inflarm_vision.executables:ball_tracker',
            'inflarm-calibrate-camera = inflarm_vision.calibration_cli:main',
            'camera_driver = inflarm_vision.executables:camera_driver',
        ],
    },
)
