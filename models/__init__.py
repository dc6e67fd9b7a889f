"""The SDF models and package.xml, installed as the package data trajectotree.models (see pyproject.toml)."""
