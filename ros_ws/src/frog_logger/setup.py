from setuptools import find_packages, setup

package_name = 'frog_logger'

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
    maintainer='Soft robot stack developers',
    maintainer_email='dev@soft-robot-stack.invalid',
    description='Rosbag-free recorder node writing raw CDR messages to MCAP, and the frog-log tool',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'recorder = frog_logger.nodes.recorder_node:main',
            'frog-log = frog_logger.cli:main',
        ],
    },
)
