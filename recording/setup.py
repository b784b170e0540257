from setuptools import find_packages, setup

package_name = 'recording'

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
    description='Record, replay, repair and analyse rosbag2 bags.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'recorder = recording:recorder_main',
            'replay = recording:replay_main',
            'bag_analysis = recording.analysis:main',
            'bag_repair = recording.repair:main',
        ],
    },
)
