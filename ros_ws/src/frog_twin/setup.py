from setuptools import find_packages, setup

package_name = 'frog_twin'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', ['frog_twin/config/frog_graph.yaml']),
    ],
    package_data={package_name: ['config/*.yaml']},
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='Soft robot stack developers',
    maintainer_email='dev@soft-robot-stack.invalid',
    description='Composition of the frog packages: digital twin, closed-loop evaluator, metrics and plots',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'frog-planner-eval = frog_twin.eval_cli:main',
            'image_preview = frog_twin.nodes.image_preview:main',
            'frog-twin = frog_twin.twin:main',
            'frog-outside-faults = frog_twin.outside_faults:main',
        ],
    },
)
