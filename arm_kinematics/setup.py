from setuptools import find_packages, setup

package_name = 'arm_kinematics'

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
    description='The arm kinematics node: end-effector pose and inverse kinematics on request.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'kinematics_node = arm_kinematics:kinematics_node_main',
        ],
    },
)
