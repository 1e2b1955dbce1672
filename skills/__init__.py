"""The shipped skills as package data (``sctd_skills``): the YAML files, their model
files and the demonstrations they were learned from. ``sctd.skill.catalog`` finds a
skill here by name (``sctd run --skill pour``)."""
