from glob import glob

from setuptools import find_packages, setup

package_name = 'rad_planner'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='rad developers',
    maintainer_email='dev@rad.local',
    description='rad planning nodes: allocation, sequencer, assembly planning and execution.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'allocation_node = rad_planner.allocation_node:main',
            'assembly_node = rad_planner.assembly_node:main',
            'sequencer_node = rad_planner.sequencer_node:main',
            'graph = rad_planner.graph:main',
            'demo = rad_planner.demo:main',
            'calibration_recorder = rad_planner.calibration_recorder:main',
            'lifecycle_manager = rad_planner.lifecycle_manager:main',
            'bag = rad_planner.bag:main',
        ],
    },
)
