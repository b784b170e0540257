from glob import glob

from setuptools import find_packages, setup

package_name = 'world_description'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/worlds', glob('worlds/*.yaml')),
        ('share/' + package_name + '/worlds/config', glob('worlds/config/*.yaml')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='robot-sim maintainers',
    maintainer_email='maintainers@example.org',
    description='The worlds and the cell (no ROS): world files, their schema and validation, '
                'resources, camera geometry.',
    license='Apache-2.0',
)
