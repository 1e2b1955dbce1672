"""Package discovery: ``sim/`` installs as ``sctd_sim``, ``services/`` as
``sctd_services`` (import names that cannot collide with other packages), ``skills/`` as the
package data ``sctd_skills`` (the shipped skills, their model files and
demonstrations, found by name: ``sctd run --skill pour``) and ``tasks/`` as ``sctd_tasks``
(the shipped task files: ``sctd sim --task pour``). Whatever else an installed
command reads ships as package data too: the Zenoh config templates ``sctd certs``
renders (``sctd/deploy/zenoh/``), the tasks and skills the commands take when not told
(``sctd/app/defaults.yaml``), the input maps, the robot model and its CAN database.
Metadata is in pyproject.toml."""

from setuptools import find_packages, setup

MAPPED = {"sctd_sim": "sim", "sctd_services": "services", "sctd_skills": "skills", "sctd_tasks": "tasks"}

packages = find_packages(include=["sctd", "sctd.*"])
for name, folder in MAPPED.items():
    packages += [name] + [f"{name}.{p}" for p in find_packages(folder)]

setup(
    packages=packages,
    package_dir=MAPPED,
    package_data={"sctd.deploy": ["zenoh/*.json5"],  # the Zenoh configs `sctd certs` renders
                  "sctd.app": ["defaults.yaml"],  # the tasks and skills commands take when not told
                  "sctd_sim": ["*.dbc", "robot/*", "robot/**/*"],
                  # sctd try's page (and the devices' script and style it shares), sctd study run's pages
                  "sctd_services": ["input/maps/*.yaml", "tryout/*.html", "tryout/*.js", "tryout/*.css",
                                    "study/*.html"],
                  "sctd_skills": ["*.yaml", "*.npz", "*.md", "sets/*.yaml", "demos/*/*.csv",
                                  "demos/*/*.json"],
                  "sctd_tasks": ["*.yaml", "*.md"]},
)
