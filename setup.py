"""Installation script for pilco: PILCO model-based RL on GPflow."""
from setuptools import find_packages, setup

with open("README.md", encoding="utf-8") as fh:
    long_description = fh.read()

setup(
    name="pilco",
    version="0.1.0",
    description="PILCO (Probabilistic Inference for Learning COntrol) on GPflow: "
    "moment-matching GP dynamics, RBF policies, compiled rollouts.",
    long_description=long_description,
    long_description_content_type="text/markdown",
    packages=find_packages(include=["pilco", "pilco.*"]),
    python_requires=">=3.10,<3.13",
    # `pilco run|sweep|diagnose|tasks`, the same as `python -m pilco`
    entry_points={"console_scripts": ["pilco = pilco.command:main"]},
    install_requires=[
        # gpflow 2.11 is built against numpy 1.x
        "numpy>=1.24,<2",
        "scipy>=1.10",
        "tensorflow>=2.16,<2.22",
        "tf-keras>=2.16,<2.22",
        "tensorflow-probability>=0.24,<0.26",
        "gpflow==2.11.2",
        "gymnasium>=1.0,<1.5",
        "tqdm>=4.60",
        # one BLAS thread in a run: the same rounding alone and in a sweep
        "threadpoolctl>=3.1",
        "matplotlib>=3.6",
    ],
    extras_require={
        # The Fetch arm of the reacher examples. mujoco 3.12+ breaks Fetch construction.
        "robotics": [
            "gymnasium-robotics==1.4.2",
            "mujoco>=3.3,<3.12",
        ],
        "examples": [
            "gymnasium-robotics==1.4.2",
            "mujoco>=3.3,<3.12",
            "imageio>=2.20",
        ],
        # python -m pilco.sweep: many seeds on a local Ray or a Ray cluster
        "sweep": [
            "ray>=2.60,<2.61",
        ],
        "tests": [
            "ray>=2.60,<2.61",
            "gymnasium-robotics==1.4.2",
            "mujoco>=3.3,<3.12",
            "imageio>=2.20",
            "pytest>=7",
            "pytest-timeout>=2.1",
            "pytest-xdist>=3.2",
            "nbmake>=1.4",
            "ipykernel>=6",
            # `ruff check .` in CI (.ci/run); ruff.toml holds the rules
            "ruff==0.17.5",
        ],
    },
)
