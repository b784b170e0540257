from setuptools import find_packages, setup

package_name = 'cell_layout'

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
    description='The pipeline cell as its world file and robot models describe it, no ROS: '
                'stands, places, drops and paths, what each arm reaches, the joints\' limits.',
    license='Apache-2.0',
)
