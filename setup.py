"""The build's one step pyproject.toml cannot say: the checkout's top-level configs/ ship inside the package, as
selpres/configs/ (a checkout and an install compose the same files: selpres.run.config.CONFIG_DIR). Everything else
is in pyproject.toml; the wheel holds the library only (no study or benchmark: those are studies/'s distribution)."""

from setuptools import find_namespace_packages, setup

LIBRARY = find_namespace_packages(include=["selpres", "selpres.*", "hydra_plugins", "hydra_plugins.*"])

setup(packages=[*LIBRARY, "selpres.configs"], package_dir={"selpres.configs": "configs"})
