"""ament_python package rig_testing (see package.xml)."""

from xml.etree import ElementTree

from setuptools import setup

package_name = "rig_testing"

setup(
    name=package_name,
    version="0.1.0",
    packages=[package_name],
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    package_data={package_name: ["py.typed"]},
    install_requires=["rig_runtime", "numpy>=1.26", "psutil>=5.9"],
    zip_safe=False,
    extras_require={"test": ["pytest"]},
    maintainer="Pitching-wing rig maintainers",
    maintainer_email="maintainers@pitching-wing.invalid",
    description=ElementTree.parse("package.xml").findtext("description"),
    license="Apache-2.0",
    python_requires=">=3.11",
    entry_points={
        "console_scripts": [
            "talker = rig_testing.talker:main",
            "listener = rig_testing.listener:main",
        ],
    },
)
