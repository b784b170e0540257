from setuptools import find_packages, setup

package_name = 'live_view'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/layouts', ['layouts/pipeline_cell.json']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='robot-sim maintainers',
    maintainer_email='maintainers@example.org',
    description='A Foxglove live bridge: every topic of a running graph, as received.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'live_view = live_view:live_view_main',
            'live_view_layout = live_view.layout:main',
        ],
    },
)
