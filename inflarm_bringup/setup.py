from glob import glob

from setuptools import find_packages, setup

package_name = 'inflarm_bringup'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml') + glob('config/*.xml')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
        ('share/' + package_name + '/rviz', glob('rviz/*.rviz')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='inflarm developers',
    maintainer_email='dev@inflarm.org',
    description='The inflarm systems: launcher, launch files, RViz, the tools that join the '
                'algorithms with the simulated or real robots.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'live_view = inflarm_bringup.executables:live_view',
            'inflarm-launch = inflarm_bringup.launcher:main',
            'inflarm-demo = inflarm_bringup.demo:main',
            'inflarm-build-knowledge = inflarm_bringup.knowledge_cli:main',
            'inflarm-estimate-bag = inflarm_bringup.bag_estimate:main',
            'inflarm-identify-plant = inflarm_bringup.identify_plant:main',
            'inflarm-bag-regression = inflarm_bringup.bag_regression:main',
            'inflarm-sra-experiments = inflarm_bringup.sra_experiments:main',
            'inflarm-repulsion-figure = inflarm_bringup.repulsion:main',
        ],
    },
)
