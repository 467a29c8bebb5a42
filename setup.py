"""ament_python package lvws_ros.

With colcon (`colcon build --paths . msg_defs`) setup.cfg sends the executables to
`<prefix>/lib/lvws_ros/`, where `ros2 run lvws_ros <exe>` finds them. With pip (the
`make env` path) they land in `bin/`; the Makefile links them into `lib/lvws_ros/` so
the virtual environment is the same ament prefix a colcon install would be.
"""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "lvws_ros"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(include=[PACKAGE, f"{PACKAGE}.*"]),
    package_data={PACKAGE: ["py.typed"], f"{PACKAGE}.learning": ["models/*.pt", "models/*.json"],
                  f"{PACKAGE}.ros": ["dashboard.html"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", sorted(glob("config/*"))),
    ],
    install_requires=["setuptools"],
    extras_require={"test": ["pytest"]},  # colcon test runs the suite with pytest
    zip_safe=False,
    maintainer="lvws_ros maintainers",
    maintainer_email="maintainers@lvws-ros.org",
    description="LVWS heterogeneous multi-robot scheduling with subteaming and waiting.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "lvws = lvws_ros.cli.main:main",
            "scheduler = lvws_ros.ros.scheduler_node:main",
            "cell_sim = lvws_ros.ros.cell_sim_node:main",
            "recorder = lvws_ros.ros.recorder:main",
            "fake_robots = lvws_ros.robot.fake:main",
            "dispatcher = lvws_ros.ros.dispatcher_node:main",
        ],
    },
)
