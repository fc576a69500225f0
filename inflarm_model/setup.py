from glob import glob

from setuptools import find_packages, setup

package_name = 'inflarm_model'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
        ('share/' + package_name + '/urdf', glob('urdf/*.urdf')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='inflarm developers',
    maintainer_email='dev@inflarm.org',
    description='Kinematics and physics of the inflatable-link arm and the pneumatic soft arm.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'inflarm-characterize = inflarm_model.characterize_cli:main',
            'robot_description = inflarm_model.executables:robot_description',
        ],
    },
)
