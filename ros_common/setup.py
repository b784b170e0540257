from setuptools import find_packages, setup

package_name = 'ros_common'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config',
         ['config/fastdds.xml', 'config/fastdds_network.xml']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='robot-sim maintainers',
    maintainer_email='maintainers@example.org',
    description='What every node of the project repeats: start-up and shutdown, stamps, '
                'geometry_msgs helpers, parameter descriptors.',
    license='Apache-2.0',
)
