"""Package discovery: each top-level source folder installs as ``impactpipe.<folder>``.

pyproject.toml holds the project's metadata; this file only maps the folders onto the
``impactpipe`` namespace and finds their subpackages, so a new subfolder (with an
``__init__.py``) is installed without editing any build file.
"""

from setuptools import find_packages, setup

#: The top-level folders that are packages of the distribution, bottom layer first.
PACKAGE_FOLDERS = ("storage", "hydro", "handoff", "nbody", "analysis", "pipeline")
#: Folders of data files inside a package (no ``__init__.py``; their files are package data).
DATA_PACKAGES = ("impactpipe.pipeline.data",)

package_dir = {f"impactpipe.{folder}": folder for folder in PACKAGE_FOLDERS}
packages = [
    name
    for folder in PACKAGE_FOLDERS
    for name in [f"impactpipe.{folder}"] + [f"impactpipe.{folder}.{sub}" for sub in find_packages(folder)]
] + list(DATA_PACKAGES)

setup(package_dir=package_dir, packages=packages)
