from setuptools import find_packages, setup

package_name = 'sim_bridge'

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
    description='PyBullet simulator node for ROS 2.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'sim_node = sim_bridge:sim_node_main',
        ],
    },
)
