from setuptools import find_packages, setup

package_name = 'controllers'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='robot-sim maintainers',
    maintainer_email='maintainers@example.org',
    description='The robots\' motion cores, without ROS: base kinematics, command safety, '
                'arm kinematics and IK, trajectories, paths and their follower.',
    license='Apache-2.0',
)
