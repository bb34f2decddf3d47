"""ament_python build of ssi_bridge: executables go to lib/ssi_bridge/ so `ros2 run` finds them."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "ssi_bridge"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(include=[PACKAGE, f"{PACKAGE}.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", glob("config/*")),
        (f"share/{PACKAGE}/launch", glob("launch/*.launch.py")),
    ],
    install_requires=["setuptools"],
    # colcon test runs pytest (not unittest) only for packages that declare it as a test extra
    extras_require={"test": ["pytest"]},
    zip_safe=True,
    maintainer="ssi_bridge maintainers",
    maintainer_email="ssi-bridge@example.com",
    description="ROS 2 bridge for SSI encoders on an XN-1SSI module behind a CANopen gateway",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            f"ssi_bridge_node = {PACKAGE}.tools.ssi_bridge_node:main",
            f"ssi_bridge_managed_node = {PACKAGE}.tools.ssi_bridge_managed_node:main",
            f"replay = {PACKAGE}.tools.replay:main",
            f"plot = {PACKAGE}.tools.plot:main",
            f"monitor = {PACKAGE}.tools.monitor:main",
            f"commission = {PACKAGE}.tools.commission:main",
            f"station = {PACKAGE}.sim.program:main",
        ],
    },
)
