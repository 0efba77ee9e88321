from setuptools import find_packages, setup

package_name = 'frog_vision'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    package_data={package_name: ['data/*.yaml']},
    include_package_data=True,
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='Soft robot stack developers',
    maintainer_email='dev@soft-robot-stack.invalid',
    description='AprilTag tracking of the frog robot from an overhead camera',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'camera_sim = frog_vision.nodes.camera_sim:main',
            'tracker_node = frog_vision.nodes.tracker_node:main',
            'camera_node = frog_vision.nodes.camera_node:main',
            'frog-vision = frog_vision.cli:main',
        ],
    },
)
