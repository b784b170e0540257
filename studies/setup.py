from glob import glob

from setuptools import find_packages, setup

package_name = 'studies'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/study_files', glob('study_files/*.yaml')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='robot-sim maintainers',
    maintainer_email='maintainers@example.org',
    description='Studies of the pipeline cell: trials as process groups, campaigns (locally '
                'or on Ray), sweeps, re-runs, comparisons, reports and storyboards.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'run_trials = studies.run_trials:main',
            'compare_runs = studies.compare:main',
            'storyboard = studies.storyboard:main',
            'pipeline_diagram = studies.pipeline_diagram:main',
        ],
    },
)
