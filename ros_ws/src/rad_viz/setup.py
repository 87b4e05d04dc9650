from glob import glob

from setuptools import find_packages, setup

package_name = 'rad_viz'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml', 'README.md']),
        ('share/' + package_name + '/config', glob('config/*.yaml') + glob('config/*.rviz')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='rad developers',
    maintainer_email='dev@rad.local',
    description='rad visualizers: the node graph to Rerun, and markers for RViz.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'viz_node = rad_viz.viz_node:main',
            'markers_node = rad_viz.markers_node:main',
        ],
    },
)
