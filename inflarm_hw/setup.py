from glob import glob

from setuptools import find_packages, setup

package_name = 'inflarm_hw'

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
    description='Hardware bridges to motors and valves, and the simulated robots, camera and MCU.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'demo_joint_publisher = inflarm_hw.executables:demo_joint_publisher',
            'joint_state_monitor = inflarm_hw.executables:joint_state_monitor',
            'sra_sim = inflarm_hw.executables:sra_sim',
            'arm_sim = inflarm_hw.executables:arm_sim',
            'bag_recorder = inflarm_hw.executables:bag_recorder',
            'bag_player = inflarm_hw.executables:bag_player',
            'hw_bridge = inflarm_hw.executables:hw_bridge',
            'sim_mcu = inflarm_hw.executables:sim_mcu',
        ],
    },
)
