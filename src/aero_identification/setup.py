"""ament_python package aero_identification (see package.xml)."""

from xml.etree import ElementTree

from setuptools import setup

package_name = "aero_identification"

setup(
    name=package_name,
    version="0.1.0",
    packages=[package_name],
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    package_data={package_name: ["py.typed"]},
    install_requires=[
        "rig_runtime",
        "multisine_gen",
        "numpy>=1.26",
        "scipy>=1.11",
        "scikit-learn>=1.3",
        "numba>=0.59",
        "matplotlib>=3.7",
        "h5py>=3.8",
        "dask[distributed]>=2024.1",  # scan_pnlss and other many-fit jobs (scan.py)
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
            "identifier = aero_identification.identifier_node:main",
        ],
    },
)
