"""bake-ray: runs ibl-bake RON pipelines on a Ray cluster (see `bake-ray run --help`)."""

from .executor import BakeRayError, run

__all__ = ["BakeRayError", "run"]
__version__ = "0.1.0"
