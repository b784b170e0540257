from setuptools import find_packages, setup

package_name = 'trial_record'

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
    description='A trial\'s record, no ROS: the run\'s events, the score against the ground '
                'truth, the result file written once and every record read back checked.',
    license='Apache-2.0',
)
