from setuptools import find_packages, setup

package_name = 'coordinator'

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
    description='The pipeline coordinator: the cell\'s controller (its two machines, layout '
                'and rules) and the node that runs it during a trial, scoring its result.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'coordinator_node = coordinator:coordinator_node_main',
        ],
    },
)
