from setuptools import find_packages, setup

package_name = 'rad_core'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={'rad_core': ['learning/weights/*.pt']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='rad developers',
    maintainer_email='dev@rad.local',
    description='Pure-Python core of rad: blocks, scenes, MDP, allocation, physics.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'rad = rad_core.cli:main',
        ],
    },
)
