from setuptools import setup

package_name = 'inflarm_tests'

# The workspace's test suite as a package of its own, so that `colcon test` runs it: colcon runs
# `python -m pytest` in this folder (colcon_core's pytest step, chosen by the 'test' extra below),
# which collects every test under tests/ with the workspace's settings (../pyproject.toml).
setup(
    name=package_name,
    version='0.1.0',
    packages=[],
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools'],
    extras_require={'test': ['pytest']},
    zip_safe=True,
    maintainer='inflarm developers',
    maintainer_email='dev@inflarm.org',
    description='The inflarm test suite: cores, nodes in-process, systems over DDS.',
    license='Apache-2.0',
)
