from glob import glob

from setuptools import find_packages, setup

package_name = 'robot_description'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/urdf', glob('urdf/*.urdf')),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='robot-sim maintainers',
    maintainer_email='maintainers@example.org',
    description='URDF descriptions of the project robots.',
    license='Apache-2.0',
    entry_points={'console_scripts': [
        'generate_urdf = robot_description.generate_urdf:main',
    ]},
)
