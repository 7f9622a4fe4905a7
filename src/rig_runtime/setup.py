"""ament_python package rig_runtime (see package.xml)."""

from xml.etree import ElementTree

from setuptools import setup

package_name = "rig_runtime"

setup(
    name=package_name,
    version="0.1.0",
    packages=[package_name],
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    package_data={package_name: ["py.typed", "fastdds_profiles.xml"]},
    install_requires=[
        "numpy>=1.26",
        "pyyaml>=6",
        "rosbags>=0.10",
        "mcap>=1.2",
        "zstandard>=0.22",
        "lz4>=4",
        "psutil>=5.9",
    ],
    zip_safe=False,
    extras_require={"test": ["pytest"]},
    maintainer="Pitching-wing rig maintainers",
    maintainer_email="maintainers@pitching-wing.invalid",
    description=ElementTree.parse("package.xml").findtext("description"),
    license="Apache-2.0",
    python_requires=">=3.11",
    entry_points={
        "console_scripts": [
            "recorder = rig_runtime.recorder:main",
            "rig-launch = rig_runtime.launcher:main",
        ],
    },
)
