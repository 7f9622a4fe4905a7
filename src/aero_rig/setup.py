"""ament_python package aero_rig (see package.xml)."""

from glob import glob
from xml.etree import ElementTree

from setuptools import setup

package_name = "aero_rig"

setup(
    name=package_name,
    version="0.1.0",
    packages=[package_name, package_name + ".cli", package_name + ".view"],
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/launch", glob("launch/*.py") + glob("launch/*.yaml")),
        ("share/" + package_name + "/config", glob("config/*.yaml")),
    ],
    package_data={package_name: ["py.typed"]},
    install_requires=[
        "rig_runtime",
        "multisine_gen",
        "pitch_actuator",
        "pressure_scanner",
        "wing_sim",
        "aero_identification",
        "pyyaml>=6",
        "tqdm>=4",
        "rerun-sdk>=0.41",
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
            "aero-rig = aero_rig.cli:main",
            "view = aero_rig.view.node:main",
        ],
    },
)
