"""ament_python package definition; also installs with pip into a plain venv."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "grasp_safety_ros"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(include=[PACKAGE, f"{PACKAGE}.*"]),
    package_data={PACKAGE: ["data/*.yaml", "data/*.yml", "data/*.xml"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", glob("config/*.yaml")),
        (f"share/{PACKAGE}/launch", glob("launch/*.launch.py")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="grasp_safety_ros maintainers",
    maintainer_email="grasp-safety@example.com",
    description="Minimum impact-force grasp selection for ROS 2 (Mavrakis et al., IROS 2017).",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "grasp-safety = grasp_safety_ros.cli.main:run",
            "grasp_safety_node = grasp_safety_ros.ros.node:main",
            "grasp_safety_monitor = grasp_safety_ros.ros.monitor.node:main",
        ],
    },
)
