"""ament_python package pressure_scanner (see package.xml)."""

from glob import glob
from xml.etree import ElementTree

from setuptools import setup

package_name = "pressure_scanner"

setup(
    name=package_name,
    version="0.1.0",
    packages=[package_name],
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", glob("config/*.yaml")),
    ],
    package_data={package_name: ["py.typed"]},
    install_requires=["rig_runtime", "numpy>=1.26", "pyyaml>=6", "scipy>=1.11", "numba>=0.59"],
    zip_safe=False,
    extras_require={"test": ["pytest"]},
    maintainer="Pitching-wing rig maintainers",
    maintainer_email="maintainers@pitching-wing.invalid",
    description=ElementTree.parse("package.xml").findtext("description"),
    license="Apache-2.0",
    python_requires=">=3.11",
    entry_points={
        "console_scripts": [
            "lift = pressure_scanner.lift_node:main",
            "scanner = pressure_scanner.scanner_node:main",
        ],
    },
)
