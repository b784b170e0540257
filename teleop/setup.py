from setuptools import find_packages, setup

package_name = 'teleop'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={'teleop': ['web/*.html', 'web/*.js', 'web/*.css']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='robot-sim maintainers',
    maintainer_email='maintainers@example.org',
    description='Teleoperation of a mobile base from the keyboard or a timed script.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'teleop = teleop:teleop_main',
            'control_panel = teleop:control_panel_main',
        ],
    },
)
