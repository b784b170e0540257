from glob import glob

from setuptools import find_packages, setup

package_name = 'sim_bringup'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='robot-sim maintainers',
    maintainer_email='maintainers@example.org',
    description='Bring-up configuration and demo checks.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'drive_check = sim_bringup:drive_check_main',
            'arm_move = sim_bringup:arm_move_main',
        ],
    },
)
