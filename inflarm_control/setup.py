from glob import glob

from setuptools import find_packages, setup

package_name = 'inflarm_control'

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
    description='Elastostatic inverse kinematics and PID + iterative learning pressure control.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'pressure_controller = inflarm_control.executables:pressure_controller',
            'trial_runner = inflarm_control.executables:trial_runner',
            'tip_path_demo = inflarm_control.executables:tip_path_demo',
            'elastostatic_ik = inflarm_control.executables:elastostatic_ik',
            'inflarm-ik-figures = inflarm_control.ik_figures:main',
        ],
    },
)
