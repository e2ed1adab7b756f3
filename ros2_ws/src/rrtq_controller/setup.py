from setuptools import find_packages, setup

package_name = 'rrtq_controller'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={package_name: ['py.typed']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='rrtq maintainers',
    maintainer_email='maintainers@rrtq.dev',
    description='Model-free finite-horizon Q-learning controller (actor/critic, robust '
                'zero-sum variant) and the open-loop force player.',
    license='MIT',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'controller_node = rrtq_controller.controller_node:main',
        ],
    },
)
