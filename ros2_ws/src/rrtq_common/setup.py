from setuptools import find_packages, setup

package_name = 'rrtq_common'

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
    description='What every rrtq node shares: topics, QoS, parameters, conversions, the '
                'lock-step gate, polygon geometry and the world of a scenario.',
    license='MIT',
    tests_require=['pytest'],
)
